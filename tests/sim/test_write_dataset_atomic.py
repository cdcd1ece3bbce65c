"""write_dataset is atomic: a failure part-way leaves the folder exactly as it was."""

import os

import numpy as np
import pytest

from cslx.sensor import default_sensor
from cslx.sim import load_dataset, write_dataset


def _frames(n, value):
    return np.full((n, 8, 10, 3), value, np.uint8)


def _snapshot(folder):
    return {p: (folder / p).read_bytes() for p in sorted(os.listdir(folder))}


def test_failure_after_the_frames_changes_nothing(tmp_path):
    sensor = default_sensor()
    out = tmp_path / "data"
    names = write_dataset(out, _frames(2, 10), {"h_v": np.zeros((2, 10))}, sensor)
    before = _snapshot(out)
    # An object array cannot be saved without pickle: fails after the PNGs are written.
    bad_gt = {"h_v": np.zeros((3, 10)), "junk": np.array([object()], dtype=object)}
    with pytest.raises(ValueError):
        write_dataset(out, _frames(3, 200), bad_gt, sensor)
    assert _snapshot(out) == before  # no new frame, no replaced frame, no staging folder
    images, gt, _ = load_dataset(out)
    assert list(gt["frames"]) == names and int(images.max()) == 10


def test_failure_into_a_new_folder_leaves_it_empty(tmp_path):
    out = tmp_path / "new"
    with pytest.raises(ValueError):
        write_dataset(out, _frames(1, 1), {"junk": np.array([object()])}, default_sensor())
    assert os.listdir(out) == []


def test_rewrite_replaces_the_data_set_and_names_are_checked(tmp_path):
    sensor = default_sensor()
    out = tmp_path / "data"
    write_dataset(out, _frames(2, 10), {}, sensor)
    write_dataset(out, _frames(2, 99), {}, sensor)
    images, _, _ = load_dataset(out)
    assert int(images.min()) == 99
    assert sorted(os.listdir(out)) == [
        "frame_00000.png",
        "frame_00001.png",
        "gt.npz",
        "sensor.json",
    ]
    with pytest.raises(ValueError, match="plain file name"):
        write_dataset(out, _frames(1, 1), {}, sensor, names=["../escape.png"])
