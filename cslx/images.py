"""Reading image files the way every command does: 8-bit RGB, or an error that says why.

`read_rgb(path)` decodes any image OpenCV reads (PNG, JPEG, BMP, TIFF, …) into an (H, W, 3)
uint8 RGB array: grayscale files are replicated into three channels, an alpha channel is
dropped, 16-bit files are scaled to 8 bits (value / 257, OpenCV's conversion), and a JPEG's
EXIF orientation is applied (the frame as a viewer shows it). It raises `OSError` with the
reason for a missing file, a directory, a file that is not an image, and a PNG or JPEG that
ends before its end marker: OpenCV decodes such a truncated JPEG into a frame whose lower part
is flat grey and only warns on stderr, so a copy interrupted mid-way would otherwise give
centres from half a frame with exit status 0.

`IMAGE_EXTENSIONS` are the file endings that a folder given to `cslx calibrate --images` or
`cslx track --source` is searched for; `list_images(folder)` lists them, sorted.
`paths_problem(paths)` is the first reason why image paths given on a command line cannot be
read (missing, a directory, a wildcard pattern the shell did not expand), in one line.

No numerics: NumPy and OpenCV for decoding, the standard library for the checks.
"""

from __future__ import annotations

import os

__all__ = ["IMAGE_EXTENSIONS", "list_images", "paths_problem", "read_rgb", "truncation_problem"]

#: File endings of the images searched for in a folder (lower case; matched case-blind).
IMAGE_EXTENSIONS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")

_PNG_SIGNATURE = b"\x89PNG\r\n\x1a\n"
_PNG_IEND = b"IEND\xaeB`\x82"  # the IEND chunk's type and CRC: the last 8 bytes of a PNG
_JPEG_SOI = b"\xff\xd8"
_JPEG_EOI = b"\xff\xd9"
#: Bytes at a file's end searched for the end marker: writers may pad or append trailers.
_TAIL = 4096


def list_images(folder: str) -> list[str]:
    """The image files (`IMAGE_EXTENSIONS`) directly inside `folder`, sorted by name."""
    names = sorted(
        f
        for f in os.listdir(folder)
        if f.lower().endswith(IMAGE_EXTENSIONS) and not os.path.isdir(os.path.join(folder, f))
    )
    return [os.path.join(folder, f) for f in names]


def paths_problem(paths: list[str]) -> str | None:
    """The first problem with the image paths (missing, a directory), or None.

    A directory names the images it holds by their ending (or says it holds none); a missing
    path with wildcards is a pattern the shell left as it was (it matched nothing) or that
    quotes kept from the shell.
    """
    import glob

    for path in paths:
        if os.path.isdir(path):
            images = list_images(path)
            if not images:
                return f"{path}: is a directory with no images in it (PNG, JPEG, BMP, TIFF)"
            ends = sorted({os.path.splitext(f)[1] for f in images})
            example = " ".join(os.path.join(path, f"*{e}") for e in ends)
            return f"{path}: is a directory; give the image files in it (e.g. {example})"
        if not os.path.exists(path):
            if glob.has_magic(path):
                n = len(glob.glob(path))
                if n:
                    return (
                        f"{path}: no such file; it is a pattern matching {n} file"
                        f"{'s' if n > 1 else ''}: write it without quotes so that the shell "
                        "expands it"
                    )
                return f"{path}: no file matches this pattern; check the folder and the ending"
            return f"{path}: no such file; check the path"
    return None


def truncation_problem(path: str) -> str | None:
    """Why a PNG or JPEG file is cut short, or None (other formats are not checked).

    A PNG must end with its IEND chunk and a JPEG must hold its end-of-image marker (FF D9)
    in the last `_TAIL` bytes; inside a JPEG's compressed data FF is always followed by 00
    or a restart marker, so FF D9 there is the end of the image.
    """
    with open(path, "rb") as f:
        head = f.read(8)
        f.seek(0, os.SEEK_END)
        size = f.tell()
        f.seek(max(0, size - _TAIL))
        tail = f.read()
    if head.startswith(_PNG_SIGNATURE):
        if _PNG_IEND not in tail:
            return "truncated PNG file (no IEND chunk at its end: an incomplete copy?)"
    elif head.startswith(_JPEG_SOI):
        if _JPEG_EOI not in tail:
            return "truncated JPEG file (no end-of-image marker: an incomplete copy?)"
    return None


def read_rgb(path: str | os.PathLike):
    """(H, W, 3) uint8 RGB pixels of an image file (module docstring: gray, alpha, 16-bit).

    Raises:
        OSError: no such file, a directory, a truncated PNG or JPEG, or not an image that
            OpenCV can decode; the message gives the reason without the path.
    """
    import cv2

    path = os.fspath(path)
    if os.path.isdir(path):
        raise IsADirectoryError("is a directory, not an image")
    if not os.path.isfile(path):
        raise FileNotFoundError("no such file")
    why = truncation_problem(path)
    if why:
        raise OSError(why)
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)  # gray → 3 channels, alpha dropped, 16 → 8 bit
    if bgr is None:
        raise OSError("not a readable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
