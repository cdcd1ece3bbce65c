"""Chessboard corners (OpenCV, sub-pixel) and the board's model points.

Step 1 of the camera calibration (paper section 2.3): the corners that Zhang's method
and the Levenberg–Marquardt refinement start from.
"""

from __future__ import annotations

import os
from collections.abc import Sequence

import numpy as np

#: search window; the issue's "5×5 window" is this half size, the value OpenCV's samples use).
SUBPIX_WIN = (5, 5)
SUBPIX_CRITERIA = (3, 30, 0.1)  # cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.1

_INTRINSIC_NAMES = ("fx", "fy", "u0", "v0", "k1", "k2", "p1", "p2")


def board_points(pattern: tuple[int, int], square: float) -> np.ndarray:
    """Target-frame corners (N, 3) in OpenCV's order: point c + cols·r is (c·s, r·s, 0).

    Args:
        pattern: inner corners (cols, rows), as `cv2.findChessboardCorners` takes them.
        square: side of a square (mm, or any unit: the poses come out in it).
    """
    cols, rows = pattern
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([c.ravel() * square, r.ravel() * square, np.zeros(cols * rows)], axis=1)


def _read_gray(image) -> np.ndarray:
    import cv2

    if isinstance(image, str | os.PathLike):
        img = cv2.imread(os.fspath(image), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FileNotFoundError(f"cannot read image {os.fspath(image)!r}")
        return img
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY)
    if img.ndim != 2:
        raise ValueError(f"an image must be (H, W) or (H, W, 3), got shape {img.shape}")
    if img.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {img.dtype}")
    return img


def detect_corners(
    images: Sequence, pattern: tuple[int, int], names: Sequence[str] | None = None
) -> tuple[list[np.ndarray | None], list[str]]:
    """Find chessboard corners with sub-pixel accuracy in each image.

    `cv2.findChessboardCorners`, then `cv2.cornerSubPix(win=(5, 5), zeroZone=(-1, -1),
    criteria=(EPS+COUNT, 30, 0.1))`, exactly the method of `tests/data/opencv-samples/
    reference.json`.

    Args:
        images: file paths, or uint8 arrays (H, W) or RGB (H, W, 3).
        pattern: inner corners (cols, rows).
        names: labels for the skipped list (default: the paths, or "image <i>").

    Returns:
        (corners, skipped): per image an (N, 2) float64 array of pixels in OpenCV's order, or
        None where the board was not found; and the names of the images without a board.
    """
    import cv2

    pattern = (int(pattern[0]), int(pattern[1]))
    out, skipped = [], []
    for i, image in enumerate(images):
        if names is not None:
            name = names[i]
        elif isinstance(image, str | os.PathLike):
            name = os.fspath(image)
        else:
            name = f"image {i}"
        gray = _read_gray(image)
        found, corners = cv2.findChessboardCorners(gray, pattern)
        if not found:
            out.append(None)
            skipped.append(name)
            continue
        corners = cv2.cornerSubPix(gray, corners, SUBPIX_WIN, (-1, -1), SUBPIX_CRITERIA)
        out.append(corners.reshape(-1, 2).astype(np.float64))
    return out, skipped
