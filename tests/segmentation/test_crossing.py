"""A cross turned against the image axes (cslx.segmentation.crossing): the other stripe
crossing a column profile at an angle, and a stripe leaving the frame across its axis."""

from __future__ import annotations

import math

import numpy as np
import pytest

from cslx.segmentation import extract
from cslx.segmentation.crossing import EDGE, inside, interpolated, other_stripe

H, W = 120, 200  # the frame of tests/segmentation/test_robust.py: shared programs


def _turned_cross(rng, angle_deg: float, noise: float = 2.0, other: float = 120.0):
    """Two orthogonal Gaussian stripes (s 1.3 px) turned by `angle_deg`, crossing at
    (u, v) = (100.3, 60.4); the horizontal one's true row per column. `other` is the
    vertical stripe's peak (0: a single stripe)."""
    t = math.tan(math.radians(angle_deg))
    u = np.arange(W, dtype=float)
    v_true = 60.4 + t * (u - 100.3)
    vv, uu = np.mgrid[0:H, 0:W].astype(float)
    c = math.cos(math.radians(angle_deg))
    d_h = (vv - v_true[None, :]) * c  # distance across each stripe
    d_v = (uu - 100.3 + t * (vv - 60.4)) * c
    img = 20.0 + 120.0 * np.exp(-0.5 * (d_h / 1.3) ** 2) + other * np.exp(-0.5 * (d_v / 1.3) ** 2)
    return img + rng.normal(0, noise, img.shape), v_true


def test_turned_crossing_is_interpolated_not_pulled_towards_the_other_stripe():
    rng = np.random.default_rng(21)
    img, v_true = _turned_cross(rng, 30.0)
    c = extract(img, "linked", stripe="h")
    pos = np.asarray(c.pos)
    near = np.abs(np.arange(W) - 100) <= 14
    # Within ±14 columns of the crossing the other stripe (tilted 30° from the columns) lies
    # on one side of the column profile; measured, those centres were pulled by up to 1.3 px
    # (this frame, before `crossing`); interpolated from both sides, < 0.005 px. Tolerance
    # 0.15 px: a tenth of the pull.
    assert np.isfinite(pos[near]).all()
    assert np.abs(pos - v_true)[near].max() < 0.15


def test_other_stripe_is_found_where_it_crosses_with_its_slope():
    rng = np.random.default_rng(22)
    width = math.hypot(2.5, 1.3)  # σ_t of the profile smoothed by σ 2.5
    for angle in (0.0, 20.0, 35.0):
        img, v_true = _turned_cross(rng, angle)
        valid = np.ones(W, bool)
        jc, s, found, _ = other_stripe(img, v_true, valid, width, axis=0)
        # In column units per px across: a line turned by a from the vertical, against a path
        # of slope tan a, has dj/do = −tan a / (1 + tan² a) (the band's step is 0.05).
        t = math.tan(math.radians(angle))
        assert bool(found)
        assert abs(int(jc) - 100) <= 2
        assert abs(float(s) + t / (1 + t * t)) <= 0.06
        m = np.asarray(interpolated(img, v_true, valid, width, axis=0))
        # an aligned crossing pulls nothing: not flagged; a turned one: its neighbourhood
        # only, and the columns whose profile the border cuts (within 1 σ_t of it)
        inner = (v_true > 10) & (v_true < H - 11)
        near = np.abs(np.arange(W) - 100) <= 20
        assert m[inner].any() == (angle > 0)
        assert not m[inner & ~near].any()
        assert m[(v_true < width) | (v_true > H - 1 - width)].all()


def test_single_stripe_has_no_crossing():
    rng = np.random.default_rng(24)
    img, v_true = _turned_cross(rng, 30.0, other=0.0)
    valid = np.ones(W, bool)
    _, _, found, _ = other_stripe(img, v_true, valid, math.hypot(2.5, 1.3), axis=0)
    assert not bool(found)  # nothing crosses: nothing is interpolated


@pytest.mark.parametrize("extend", [False, True])
def test_stripe_leaving_the_frame_sideways_gives_no_centres_on_the_border(extend, monkeypatch):
    from cslx.segmentation import robust

    monkeypatch.setattr(robust, "BORDER", extend)
    rng = np.random.default_rng(23)
    h, w = 160, 200  # the frame of test_robust's tilted stripe
    vv, uu = np.mgrid[0:h, 0:w].astype(float)
    u_true = 190.0 - 0.6 * (vv[:, 0] - 40)  # leaves the frame at the right above row 25
    img = 20.0 + 120.0 * np.exp(-0.5 * ((uu - u_true[:, None]) / 1.3) ** 2)
    img = img + rng.normal(0, 2.0, img.shape)
    c = extract(img, "linked", stripe="v")
    pos, valid = np.asarray(c.pos), np.asarray(c.valid)
    # no centre where the stripe is outside the frame (the border's own ridge), and the
    # last ones inside (cut profiles) not pulled off
    assert not valid[u_true > w - 1].any()
    ok = valid & (u_true < w - 1)
    assert np.abs(pos - u_true)[ok].max() < 0.3
    if not extend:  # none within EDGE of the border (`inside` drops them)
        assert np.all(np.asarray(inside(pos[valid], w)))
        assert pos[valid].max() < w - 1 - EDGE
        assert ok.sum() >= np.sum(u_true < w - 4) - 2
    else:  # those come back from the fit through the centres inside (`border`)
        assert pos[valid].max() <= w - 1
        assert ok.sum() >= np.sum(u_true < w - 1) - 1
        assert not np.all(np.asarray(inside(pos[valid], w)))
