"""Atomic outputs and up-front checks of output paths.

Every file a command or an experiment names as its output is written through this module:
the data go to a temporary file in the same folder, which replaces the target with
`os.replace` only once it is complete. An interrupted or failing writer therefore leaves
nothing at the target path — the previous file, if any, stays intact — and a reader never
sees half a file. `os.replace` is atomic on POSIX and Windows when source and target are
on the same file system, which the same folder guarantees.

- `atomic_write(path, mode)`: a file object for `with`; the target appears on a clean exit.
- `atomic_path(path)`: a temporary path for writers that take a file name (OpenCV,
  Matplotlib, NumPy); the target appears on a clean exit.
- `atomic_directory(path)`: a staging folder whose files move into `path` together on a
  clean exit (a rendered data set: frames, `sensor.json`, `gt.npz` last).
- `output_problem(path)` / `check_output_file(path)`: why a file could not be written
  there (missing or read-only folder, a directory at the path), before any work starts.

No numerics; standard library only.
"""

from __future__ import annotations

import contextlib
import os
import secrets
import shutil
from collections.abc import Iterator
from typing import IO

__all__ = [
    "OutputPathError",
    "atomic_directory",
    "atomic_path",
    "atomic_write",
    "check_output_dir",
    "check_output_file",
    "output_problem",
]


class OutputPathError(OSError):
    """An output path that cannot be written (the message says why and what to do)."""


def _temp_name(path: str) -> str:
    folder, name = os.path.split(os.path.abspath(path))
    return os.path.join(folder, f".{name}.{secrets.token_hex(4)}.tmp")


def _discard(tmp: str) -> None:
    with contextlib.suppress(FileNotFoundError):
        if os.path.isdir(tmp) and not os.path.islink(tmp):
            shutil.rmtree(tmp, ignore_errors=True)
        else:
            os.remove(tmp)


@contextlib.contextmanager
def atomic_path(path: str | os.PathLike) -> Iterator[str]:
    """A temporary path in `path`'s folder that replaces `path` when the block succeeds.

    The temporary name keeps `path`'s extension, so that writers choosing the format by
    extension (cv2.imwrite, savefig) work. On any exception (KeyboardInterrupt included) the
    temporary file is removed and `path` is left as it was.
    """
    path = os.fspath(path)
    folder, name = os.path.split(os.path.abspath(path))
    stem, ext = os.path.splitext(name)
    tmp = os.path.join(folder, f".{stem}.{secrets.token_hex(4)}.tmp{ext}")
    try:
        yield tmp
        if not os.path.exists(tmp):
            raise OSError(f"{path}: the writer produced no file")
        os.replace(tmp, path)
    except BaseException:
        _discard(tmp)
        raise


@contextlib.contextmanager
def atomic_write(
    path: str | os.PathLike,
    mode: str = "w",
    *,
    encoding: str | None = None,
    newline: str | None = None,
) -> Iterator[IO]:
    """`open(path, mode)` that writes a temporary file and moves it onto `path` at the end.

    `mode` is "w", "wt" or "wb". Text mode defaults to UTF-8. The file is flushed and synced
    before the replace; permissions follow the umask like a plain `open`.
    """
    if mode not in ("w", "wt", "wb"):
        raise ValueError(f"atomic_write writes new files only (mode 'w' or 'wb'), not {mode!r}")
    path = os.fspath(path)
    tmp = _temp_name(path)
    binary = "b" in mode
    fd = os.open(tmp, os.O_WRONLY | os.O_CREAT | os.O_EXCL, 0o666)
    try:
        with os.fdopen(
            fd,
            mode,
            encoding=None if binary else (encoding or "utf-8"),
            newline=None if binary else newline,
        ) as f:
            yield f
            f.flush()
            os.fsync(f.fileno())
        os.replace(tmp, path)
    except BaseException:
        _discard(tmp)
        raise


@contextlib.contextmanager
def atomic_directory(path: str | os.PathLike, last: tuple[str, ...] = ()) -> Iterator[str]:
    """A staging folder inside `path` whose files move into `path` when the block succeeds.

    `path` is created if missing. Files are moved one `os.replace` each (sub-folders are not
    supported), the names in `last` after all others — a data set's index file last, so that
    a reader that finds the index finds every file it lists. On an exception the staging
    folder is removed and nothing in `path` changes.
    """
    path = os.fspath(path)
    os.makedirs(path, exist_ok=True)
    stage = os.path.join(path, f".staging.{secrets.token_hex(4)}.tmp")
    os.mkdir(stage)
    try:
        yield stage
        order = {name: i + 1 for i, name in enumerate(last)}
        names = sorted(os.listdir(stage), key=lambda n: order.get(n, 0))
        for name in names:
            src = os.path.join(stage, name)
            if os.path.isdir(src):
                raise OSError(f"atomic_directory: sub-folder {name!r} is not supported")
        for name in names:
            os.replace(os.path.join(stage, name), os.path.join(path, name))
        os.rmdir(stage)
    except BaseException:
        _discard(stage)
        raise


def output_problem(path: str | os.PathLike, *, create_folder: bool = False) -> str | None:
    """Why a file could not be written at `path`, or None if it looks writable.

    Checks (without writing anything): the path is not a directory; its folder exists (or,
    with `create_folder`, the nearest existing ancestor is a writable directory) and is a
    writable directory; an existing file is writable.
    """
    path = os.fspath(path)
    if not path:
        return "empty output path"
    if os.path.isdir(path):
        return "is a directory; give a file name"
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        if not create_folder:
            if os.path.exists(folder):
                return f"{folder} is not a directory"
            return f"folder {folder} does not exist; create it first"
        probe = folder
        while not os.path.exists(probe):
            probe = os.path.dirname(probe)
        if not os.path.isdir(probe):
            return f"{probe} is not a directory"
        folder = probe
    if not os.access(folder, os.W_OK | os.X_OK):
        return f"folder {folder} is not writable"
    if os.path.exists(path) and not os.access(path, os.W_OK):
        return "file exists and is not writable"
    return None


def check_output_file(path: str | os.PathLike, *, create_folder: bool = False) -> None:
    """Raise `OutputPathError` with `output_problem`'s reason if `path` cannot be written."""
    why = output_problem(path, create_folder=create_folder)
    if why is not None:
        raise OutputPathError(f"{os.fspath(path)}: {why}")


def check_output_dir(path: str | os.PathLike) -> None:
    """Raise `OutputPathError` if `path` is neither a writable folder nor creatable as one."""
    path = os.fspath(path)
    if os.path.exists(path) and not os.path.isdir(path):
        raise OutputPathError(f"{path}: exists and is not a directory; give a folder")
    why = output_problem(os.path.join(path, "x"), create_folder=True)
    if why is not None:
        raise OutputPathError(f"{path}: {why}")
