"""A stripe turned far from its search axis (cslx.segmentation.orient): its direction,
smoothing along it, and the path's pieces along the other stripe of the cross."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cslx.segmentation import extract, orient
from cslx.segmentation.steger import _filter_axis

H, W = 120, 200  # the frame of tests/segmentation/test_robust.py: shared programs


def _cross(rng, a_h: float, a_v: float, noise: float = 2.0):
    """Two Gaussian stripes (s 1.3 px) at angles a_h and a_v (degrees from the u axis,
    positive towards +v) through (u, v) = (100.3, 60.4); the first one's true row per
    column (NaN outside the frame)."""
    u = np.arange(W, dtype=float)
    vv, uu = np.mgrid[0:H, 0:W].astype(float)
    img = np.full((H, W), 20.0)
    for a in (a_h, a_v):
        n = (-math.sin(math.radians(a)), math.cos(math.radians(a)))  # normal
        d = (uu - 100.3) * n[0] + (vv - 60.4) * n[1]
        img = img + 120.0 * np.exp(-0.5 * (d / 1.3) ** 2)
    v_true = 60.4 + math.tan(math.radians(a_h)) * (u - 100.3)
    v_true[(v_true < 0) | (v_true > H - 1)] = np.nan
    return img + rng.normal(0, noise, img.shape), v_true


def test_directions_of_a_cross_turned_45_degrees():
    rng = np.random.default_rng(31)
    img, _ = _cross(rng, 46.5, -50.0)  # the rolled rig's angles (experiments.ood_extraction)
    angle, other = orient.peak_angles(np.asarray(orient.direction_histogram(img)))
    # the nearer peak is the stripe searched column by column; 1° bins, 4 × 4 blocks
    assert abs(angle - 46.5) < 1.5 and abs(other + 50.0) < 1.5
    slope, other_slope = orient.search_slope(img)
    assert abs(slope - math.tan(math.radians(46.5))) < 0.06
    # an aligned cross is left to the image axes (below MIN_DEG)
    img0, _ = _cross(rng, 2.0, 91.0)
    assert orient.search_slope(img0) == (None, None)


def test_smooth_along_is_the_axis_filter_at_slope_zero_and_follows_a_slope():
    rng = np.random.default_rng(32)
    x = rng.normal(size=(80, 60)).astype(np.float32)
    a = np.asarray(orient.smooth_along(x, 0.0, sigma=3.0))
    (b,) = _filter_axis(x, 3.0, (0,), 0)
    assert np.allclose(a, np.asarray(b), atol=1e-5)
    # a line of slope 0.8 (along axis 0, across axis 1) keeps its profile when smoothed
    # along it, and is smeared when smoothed along the axis
    u, v = np.mgrid[0:80, 0:60].astype(np.float32)
    line = np.exp(-0.5 * ((v - 10.2 - 0.8 * (u - 20)) / 1.2) ** 2).astype(np.float32)
    along = np.asarray(orient.smooth_along(line, 0.8, sigma=3.0))[40]
    (axis,) = _filter_axis(line, 3.0, (0,), 0)
    assert along.max() > 0.9 and np.asarray(axis)[40].max() < 0.5
    assert abs(np.argmax(along) - (10.2 + 0.8 * 20)) <= 1


def test_drop_other_drops_a_piece_along_the_other_stripe():
    j = np.arange(300, dtype=float)
    pos = 1.05 * j + 5.0  # this stripe, slope 1.05
    pos[:100] = 200.0 - 1.19 * j[:100]  # a piece along the other stripe (slope −1.19)
    valid = np.ones(300, bool)
    valid[100:130] = False  # the gap the path jumped across
    kept = orient.drop_other(pos, valid, 1.05, -1.19)
    assert not kept[:100].any() and kept[130:].all()
    # no other stripe known: nothing dropped
    assert (orient.drop_other(pos, valid, 1.05, None) == valid).all()


@pytest.mark.slow
def test_a_cross_turned_45_degrees_is_extracted_along_each_stripe():
    rng = np.random.default_rng(33)
    img, v_true = _cross(rng, 46.5, -50.0)
    c = extract(img, "linked", stripe="h")
    pos, valid = np.asarray(c.pos), np.asarray(c.valid)
    inner = np.isfinite(v_true) & (v_true > 6) & (v_true < H - 7)
    inner &= np.abs(np.arange(W) - 100.3) > 12  # the crossing: `crossing` interpolates it
    # Without `orient` the path followed the other stripe over part of the frame (errors of
    # tens of px); with it, every inner column is found on this stripe.
    assert valid[inner].mean() > 0.95
    err = np.abs(pos - v_true)[inner & valid]
    assert np.median(err) < 0.1 and err.max() < 0.5
    assert not valid[~np.isfinite(v_true)].any()


def test_trim_ends_cuts_a_tail_below_half_the_plateau_strength():
    z = np.full(200, 100.0)
    z[5:15] = np.linspace(5.0, 45.0, 10)  # the erf ramp past a fan's end (smoothed along)
    z[15:19] = [60.0, 80.0, 95.0, 100.0]
    valid = np.ones(200, bool)
    valid[:5] = valid[190:] = False  # the path ends inside the frame at both ends
    kept = orient.trim_ends(valid, z)
    assert not kept[:15].any() and kept[15:190].all() and not kept[190:].any()


def test_trim_ends_keeps_a_path_that_reaches_the_frame_end_along():
    # a slanted stripe's first-pass strength falls to ≈ 0.43 of its plateau at the frame's
    # end along (orient.TRIM_AT_BORDER): no fan's end there, the rows are the stripe's
    z = np.full(200, 100.0)
    z[:6] = np.linspace(43.0, 48.0, 6)
    valid = np.ones(200, bool)
    assert orient.trim_ends(valid, z).all()


def test_a_cross_turned_about_45_degrees_keeps_h_and_v_under_a_small_turn():
    # Nearer the axis alone flips "h" between the stripes when a ±45° cross turns by 0.6°;
    # within TIE_DEG, "h" is the stripe falling to the right (positive angle) and "v" the
    # rising one, in both searches (`orient.peak_angles`).
    rng = np.random.default_rng(34)
    for a_pos, a_neg in ((45.3, -44.7), (44.7, -45.3)):
        img, _ = _cross(rng, a_pos, a_neg, noise=1.0)
        h, _ = orient.peak_angles(np.asarray(orient.direction_histogram(img)), 1)
        v, _ = orient.peak_angles(np.asarray(orient.direction_histogram(img.T)), -1)
        assert abs(h - a_pos) < 1.5  # the stripe at +45 from the x axis
        assert abs(v - (-90.0 - a_neg)) < 1.5  # the one at −45: −45 from the y axis
    # outside the tie the nearer stripe wins, whatever `prefer` says
    img, _ = _cross(rng, 40.0, -50.0, noise=1.0)
    h, _ = orient.peak_angles(np.asarray(orient.direction_histogram(img)), -1)
    assert abs(h - 40.0) < 1.5


def test_the_calibration_says_which_stripe_is_which():
    from cslx.sensor.rig import TABLE4_K, cross_projector_planes

    # the projector of experiments.ood_extraction's rig "roll-45" (offset turned with it)
    c, s = math.cos(math.radians(-45)), math.sin(math.radians(-45))
    planes = cross_projector_planes(
        origin=(-60.0 * (c - s), -60.0 * (s + c), 0.0), target=(40 * c, 40 * s, 230.0),
        roll_deg=-45.0,
    )  # fmt: skip
    fx, fy = TABLE4_K[0][0], TABLE4_K[1][1]
    # rendered frames of that rig (seed 7590, frames 0-1): h at -41.1 / -40.8°, v at
    # 46.5 / 46.1° from the y axis (the direction histogram)
    assert abs(orient.plane_angle(planes[0], fx, fy, 0) + 40.95) < 0.8
    assert abs(orient.plane_angle(planes[1], fx, fy, 1) - 46.3) < 0.8
    # with it, a tied cross's stripe is the one the calibration expects, against the rule
    rng = np.random.default_rng(35)
    img, _ = _cross(rng, 45.3, -44.7, noise=1.0)
    hist = np.asarray(orient.direction_histogram(img))
    assert abs(orient.peak_angles(hist, 1)[0] - 45.3) < 1.5
    assert abs(orient.peak_angles(hist, 1, expected=-40.7)[0] + 44.7) < 1.5


def test_a_single_stripe_seen_near_45_degrees_is_not_taken_by_both_searches():
    # roll45/shadow, development seed 7809 frame 0: the vertical stripe, washed out in the
    # sunlit half, left the direction histogram one peak, the horizontal stripe's (46.5°
    # from x, 43.5° from y), and the v search took it (324 gross centres). Under the tie's
    # rule it is "h" (positive angle): the v search then runs perpendicular to it.
    rng = np.random.default_rng(36)
    vv, uu = np.mgrid[0:H, 0:W].astype(float)
    n = (-math.sin(math.radians(46.5)), math.cos(math.radians(46.5)))
    d = (uu - 100.3) * n[0] + (vv - 60.4) * n[1]
    img = 20.0 + 120.0 * np.exp(-0.5 * (d / 1.3) ** 2) + rng.normal(0, 1.0, (H, W))
    h, h_other = orient.peak_angles(np.asarray(orient.direction_histogram(img)), 1)
    assert abs(h - 46.5) < 1.5 and h_other is None
    hist_v = np.asarray(orient.direction_histogram(img.T))
    v, v_other = orient.peak_angles(hist_v, -1)
    assert abs(v_other - 43.5) < 1.5 and abs(v + 46.5) < 1.5
    # with the calibration: its angle, the peak as the other stripe
    v, v_other = orient.peak_angles(hist_v, -1, expected=-40.0)
    assert v == -40.0 and abs(v_other - 43.5) < 1.5
