"""The tail past a turned stripe's end inside the frame (`cslx.segmentation.ends`)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cslx.segmentation import extract, robust
from cslx.segmentation.ends import REACH, oblique_ends

N, ACROSS = 200, 120


def _path(slope: float, start: int, tail: int, seed: int = 0):
    """A path of `slope` from column `start`, with `tail` centres before it on the row of
    its end (the first pass's tail past the fan's end) and a rough first pass (std 0.3)."""
    rng = np.random.default_rng(seed)
    j = np.arange(N, dtype=float)
    truth = 30.0 + slope * (j - start)
    pos = truth + rng.normal(0, 0.3, N)
    pos[start - tail : start] = 30.0 + 0.1 * (j[start - tail : start] - start)
    valid = j >= start - tail
    return np.where(valid, pos, np.nan), valid


def test_tail_past_a_turned_stripes_end_is_dropped():
    pos, valid = _path(0.7, 60, 12)
    kept = np.asarray(oblique_ends(np.nan_to_num(pos), valid, ACROSS))
    first = int(np.flatnonzero(kept)[0])
    # the tail (columns 48–59) goes but for its last centres within 1 px of the line (0.6 px
    # per column off it here), and ≤ 2 true centres with it
    assert 58 <= first <= 62
    assert kept[first:].all()  # the rest of the path is kept (the far end leaves the frame)


@pytest.mark.parametrize("slope, start, tail", [(0.1, 60, 12), (0.7, 0, 0), (0.7, 60, 0)])
def test_aligned_stripes_border_ends_and_clean_ends_are_left_alone(slope, start, tail):
    pos, valid = _path(slope, start, tail, seed=1)
    kept = np.asarray(oblique_ends(np.nan_to_num(pos), valid, ACROSS))
    lost = int((valid & ~kept).sum())
    # aligned: its tail lies on its line (no bias); at the border: no end inside the frame;
    # a clean end: at most a centre of the rough first pass
    assert lost <= (1 if (start and not tail) else 0)


@pytest.mark.slow  # 17 s alone (compiling the 120 × 200 frame's programs)
def test_turned_stripe_ending_inside_the_frame_has_no_centres_past_its_end(monkeypatch):
    # A single Gaussian stripe (s 1.3 px) turned 35°, its fan ending at column 60: without
    # the trim the path started at column 48, 9.4 px off the stripe's line there, and 1.1 px
    # off at column 61 (errors 9.38 … 1.09 over columns 48–61).
    rng = np.random.default_rng(6)
    t, c = math.tan(math.radians(35.0)), math.cos(math.radians(35.0))
    u = np.arange(N, dtype=float)
    v_true = 60.4 + t * (u - 100.3)
    vv, uu = np.mgrid[0:ACROSS, 0:N].astype(float)
    laser = 120.0 * np.exp(-0.5 * (((vv - v_true) * c) / 1.3) ** 2) * (uu >= 60)
    img = 20.0 + laser + rng.normal(0, 2.0, laser.shape)
    p = np.asarray(extract(img, "linked", stripe="h").pos)
    found = np.flatnonzero(np.isfinite(p))
    assert found[0] >= 60 - 1
    assert np.abs(p - v_true)[found].max() < 0.5
    monkeypatch.setattr(robust, "END_TRIM", False)
    p = np.asarray(extract(img, "linked", stripe="h").pos)
    assert np.flatnonzero(np.isfinite(p))[0] < 60 - REACH // 3  # the tail, without the trim
