"""A turned stripe leaving the frame across its search axis (cslx.segmentation.border)."""

from __future__ import annotations

import numpy as np

from cslx.segmentation import border

N, M = 200, 120  # along, across (search orientation)


def _stripe(end: float = -np.inf):
    """Image (N, M) of a stripe of slope 1.05 (s 2 px) lit where along ≥ `end`, its true
    centres, and a path that lost the centres within 12 px of the border across."""
    j = np.arange(N, dtype=float)
    # curved a little: 2e-5 px per centre², the median of the truth's quadratic term over the
    # ends extended on the development frames (1.7e-5; `border`'s docstring)
    true = 0.3 + 1.05 * (j - 40.0) + 0.00002 * (j - 40.0) ** 2
    across = np.arange(M, dtype=float)
    img = 5.0 + 100.0 * np.exp(-0.5 * ((across[None, :] - true[:, None]) / 2.0) ** 2)
    img[j < end] = 5.0
    inside = (true >= 0) & (true <= M - 1)
    pos = np.where(inside & (true > 12) & (true < M - 13), true, np.nan)
    return img, true, pos, np.isfinite(pos)


def test_the_path_is_extended_to_the_border_along_its_fit():
    img, true, pos, valid = _stripe()
    sig, z = np.full(N, 0.05), np.full(N, 50.0)
    clipped = np.zeros(img.shape, bool)
    p, v, s, st = border.extend(pos, valid, sig, z, img, clipped, 3.0)
    inside = (true >= -0.5) & (true <= M - 0.5)  # the outer pixels' area
    assert v[inside].all() and not v[~inside].any()
    assert np.nanmax(np.abs(p - true)[inside]) < 0.15
    assert (st[v] > 0).all() and np.isfinite(s[v]).all()


def test_a_fan_ending_before_the_border_is_not_extended_past_its_end():
    img, true, pos, valid = _stripe(end=50.0)  # the fan ends at along 50, 10.8 px inside
    keep = np.arange(N) >= 50
    sig, z = np.full(N, 0.05), np.full(N, 50.0)
    p, v, _, _ = border.extend(
        np.where(keep, pos, np.nan), valid & keep, sig, z, img, np.zeros(img.shape, bool), 3.0
    )
    assert not v[:50].any() and v[51:60].all()  # filled up to the fan's end only
    # a clipped core counts as lit (an unfilled run at the border is a hole in R − G)
    img, true, pos, valid = _stripe()
    hole = np.abs(np.arange(M)[None, :] - true[:, None]) < 1.5
    hole &= np.arange(N)[:, None] < 52
    img[hole] = 0.0
    p, v, _, _ = border.extend(pos, valid, sig, z, img, hole, 3.0)
    assert v[(true >= -0.5) & (true <= M - 0.5)].all()


def test_a_bias_on_the_support_is_not_amplified_into_a_gross_centre():
    """The path's centres on the support carry a smooth 0.2 px hump (the bias a sunny or cut
    profile leaves; development frames: up to 0.31 px), the stripe itself is straight: a
    quadratic through them ends 1.6 px off at the border 30 centres out, the line 0.1 px."""
    j = np.arange(N, dtype=float)
    true = 0.3 + 0.4 * (j - 40.0)  # meets the border across at along 39
    across = np.arange(M, dtype=float)
    img = 5.0 + 100.0 * np.exp(-0.5 * ((across[None, :] - true[:, None]) / 2.0) ** 2)
    valid = (true > 12) & (true < M - 13)  # the path lost the 12 px next to the border
    support = valid & (j < 100)  # its first 30 centres, along 70–99
    pos = np.where(valid, true + np.where(support, 0.2 * np.sin(np.pi * (j - 70) / 30), 0), np.nan)
    sig, z = np.full(N, 0.05), np.full(N, 50.0)
    p, v, _, _ = border.extend(pos, valid, sig, z, img, np.zeros(img.shape, bool), 3.0)
    new = v & ~valid
    assert new.sum() >= 25  # extended to the border
    assert np.abs(p - true)[new].max() < 0.3


def test_a_bend_between_the_support_and_the_border_leaves_the_end_as_it_was():
    """The stripe turns (a surface corner) 7.7 px from the border, and the path's own centres
    follow it there: the line through the support does not carry over (the zone test)."""
    j = np.arange(N, dtype=float)
    true = 0.3 + 1.05 * (j - 40.0)
    true = np.where(j < 47, true[47] + 0.5 * (j - 47), true)
    across = np.arange(M, dtype=float)
    img = 5.0 + 100.0 * np.exp(-0.5 * ((across[None, :] - true[:, None]) / 2.0) ** 2)
    valid = (true > 3) & (true < M - 4)
    pos = np.where(valid, true, np.nan)
    sig, z = np.full(N, 0.05), np.full(N, 50.0)
    p, v, _, _ = border.extend(pos, valid, sig, z, img, np.zeros(img.shape, bool), 3.0)
    low = j < 100  # the end at across 0 (the other end, straight, is extended as usual)
    assert np.array_equal(v[low], valid[low])
    assert np.allclose(p[low & v], pos[low & v])


def test_a_path_ending_at_the_border_along_is_not_extended():
    """The path lost its first 30 centres, where the stripe (10–25 px from the border across)
    runs to the frame's end along: its profiles are whole there, so the loss is not the
    border's cut and the line is not followed (development frame 7809/3 H: 8 gross centres
    60–70 px from the border across, the support's slope 0.74 against the truth's 0.6)."""
    j = np.arange(N, dtype=float)
    true = 60.0 + 0.5 * (j - 100.0)
    across = np.arange(M, dtype=float)
    img = 5.0 + 100.0 * np.exp(-0.5 * ((across[None, :] - true[:, None]) / 2.0) ** 2)
    valid = (j >= 30) & (true < M - 13)
    pos = np.where(valid, true, np.nan)
    sig, z = np.full(N, 0.05), np.full(N, 50.0)
    p, v, _, _ = border.extend(pos, valid, sig, z, img, np.zeros(img.shape, bool), 3.0)
    assert not v[:30].any()
    assert np.array_equal(v, valid)  # the other end leaves along too (at 109.5 px across)


def test_a_bend_the_path_smoothed_away_is_seen_on_the_image_along_the_border():
    """The stripe turns 30 centres before the border (slope 1.05 → 0.95) but the path's own
    centres follow the straight trend (smoothed along the path): the line would end 1.9–3.0
    px off, which the profiles along the border show (development frame 7808/3 V: 14 gross
    centres, up to 2.7 px off, with the zone test passed)."""
    j = np.arange(N, dtype=float)
    line = 0.3 + 1.05 * (j - 40.0)
    true = np.where(j < 70, line[70] + 0.95 * (j - 70), line)
    across = np.arange(M, dtype=float)
    img = 5.0 + 100.0 * np.exp(-0.5 * ((across[None, :] - true[:, None]) / 4.0) ** 2)
    valid = (line > 12) & (line < M - 13)
    pos = np.where(valid, line, np.nan)  # the path: straight through the bend
    sig, z = np.full(N, 0.05), np.full(N, 50.0)
    p, v, _, _ = border.extend(pos, valid, sig, z, img, np.zeros(img.shape, bool), 5.0)
    low = j < 100
    assert not (v & ~valid)[low].any()  # nothing set past the path's end at across 0
    assert (v & ~valid)[~low].any()  # the other, straight end is extended as usual


def test_the_last_centre_within_the_outer_pixel_and_a_corner_are_extended():
    """The truth runs to the outer pixels' edges (−0.5, M − 0.5): the line stopped at the
    outer pixel centres and lost one centre an end (42 of the 221 lost on the development
    frames of `experiments.roll_losses`, seed 7800). And a stripe that leaves by a corner
    meets the frame's end along while inside the cut zone (roll35/saturated V 7802/0: rows
    0–16, 2–10 px from the border across): the reach test refused it."""
    j = np.arange(N, dtype=float)
    across = np.arange(M, dtype=float)
    sig, z = np.full(N, 0.05), np.full(N, 50.0)
    for true in (-0.3 + 1.05 * (j - 40.0), 5.0 + 0.5 * j):
        img = 5.0 + 100.0 * np.exp(-0.5 * ((across[None, :] - true[:, None]) / 2.0) ** 2)
        valid = (true > 12) & (true < M - 13)
        pos = np.where(valid, true, np.nan)
        p, v, _, _ = border.extend(pos, valid, sig, z, img, np.zeros(img.shape, bool), 3.0)
        lost = (true >= -0.5) & (true <= 12)
        assert v[lost].all() and np.abs(p - true)[lost].max() < 0.15
