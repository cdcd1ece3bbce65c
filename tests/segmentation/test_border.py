"""A turned stripe leaving the frame across its search axis (cslx.segmentation.border)."""

from __future__ import annotations

import numpy as np

from cslx.segmentation import border

N, M = 200, 120  # along, across (search orientation)


def _stripe(end: float = -np.inf):
    """Image (N, M) of a stripe of slope 1.05 (s 2 px) lit where along ≥ `end`, its true
    centres, and a path that lost the centres within 12 px of the border across."""
    j = np.arange(N, dtype=float)
    true = 0.3 + 1.05 * (j - 40.0) + 0.0004 * (j - 40.0) ** 2  # curved a little (the lens)
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
    inside = (true >= 0) & (true <= M - 1)
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
    assert v[(true >= 0) & (true <= M - 1)].all()
