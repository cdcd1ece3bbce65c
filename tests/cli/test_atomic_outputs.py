"""cslx.files: outputs appear complete or not at all; the previous file survives a failure."""

import os

import pytest

from cslx.files import (
    OutputPathError,
    atomic_path,
    atomic_write,
    check_output_dir,
    check_output_file,
    output_problem,
)
from cslx.provenance import write_csv


def _names(folder):
    return sorted(os.listdir(folder))


@pytest.mark.parametrize("exc", [RuntimeError, KeyboardInterrupt])
def test_interrupted_write_leaves_the_old_file_and_no_temp(tmp_path, exc):
    path = tmp_path / "out.csv"
    path.write_text("old\n")
    with pytest.raises(exc):
        with atomic_write(path, "w", newline="") as f:
            f.write("image,stripe,u,v\r\n" + "a.png,h,1.0,2.0\r\n" * 1000)
            raise exc
    assert path.read_text() == "old\n"
    assert _names(tmp_path) == ["out.csv"]


def test_complete_write_replaces_and_keeps_umask_permissions(tmp_path):
    path = tmp_path / "out.bin"
    with atomic_write(path, "wb") as f:
        f.write(b"\x00\x01")
    assert path.read_bytes() == b"\x00\x01"
    umask = os.umask(0)
    os.umask(umask)
    assert (path.stat().st_mode & 0o777) == (0o666 & ~umask)
    with pytest.raises(ValueError):
        with atomic_write(path, "a"):
            pass


def test_atomic_path_for_writers_that_take_a_file_name(tmp_path):
    import cv2
    import numpy as np

    path = tmp_path / "pic.png"
    with atomic_path(path) as tmp:
        assert tmp.endswith(".png") and os.path.dirname(tmp) == str(tmp_path)
        assert cv2.imwrite(tmp, np.zeros((4, 4, 3), np.uint8))
        assert not path.exists()
    assert cv2.imread(str(path)) is not None
    with pytest.raises(OSError, match="produced no file"):
        with atomic_path(tmp_path / "never.png"):
            pass
    assert _names(tmp_path) == ["pic.png"]


def test_results_csv_is_atomic(tmp_path):
    path = tmp_path / "results.csv"
    write_csv(str(path), [{"a": 1.0, "b": "x"}])
    before = path.read_bytes()

    def rows():
        yield {"a": 2.0, "b": "y"}
        raise RuntimeError("the experiment crashed part-way")

    with pytest.raises(RuntimeError):
        write_csv(str(path), list_like(rows()), fields=["a", "b"])
    assert path.read_bytes() == before
    assert _names(tmp_path) == ["results.csv"]


class list_like:  # noqa: N801 — a sequence whose iteration fails half-way
    def __init__(self, gen):
        self.gen = gen

    def __iter__(self):
        return self.gen


def test_output_problems_are_named(tmp_path):
    assert output_problem(tmp_path / "ok.csv") is None
    assert "is a directory" in output_problem(tmp_path)
    assert "does not exist" in output_problem(tmp_path / "no" / "x.csv")
    assert output_problem(tmp_path / "no" / "deeper" / "x.csv", create_folder=True) is None
    f = tmp_path / "file"
    f.write_text("")
    assert "not a directory" in output_problem(f / "x.csv", create_folder=True)
    with pytest.raises(OutputPathError, match="not a directory"):
        check_output_dir(f)
    with pytest.raises(OutputPathError, match="is a directory"):
        check_output_file(tmp_path)
    check_output_dir(tmp_path / "new" / "folder")  # creatable: fine, nothing created
    assert not (tmp_path / "new").exists()
