"""A T whose bar meets the stem at an angle other than 90° (issue 12 generality audit,
experiments/tracking_generality.py): the held junction follows the bar along the stripe
while the robot turns (`JunctionTrack(bar_slope=True)`), and the horizontal stripe's bead
is the one near the predicted line, not the larger bar beside it (`cslx.runtime.bead_near`)."""

import math

import numpy as np
import pytest

from cslx.runtime.bead_near import bead_near
from cslx.runtime.junction_track import JunctionTrack
from cslx.runtime.line_filter import KalmanConfig
from cslx.runtime.weld import WeldConfig


def _track(bar_slope: bool) -> JunctionTrack:
    c = KalmanConfig()
    return JunctionTrack(
        c.junction_window,
        c.junction_tol_mm,
        c.junction_hold,
        c.junction_unseen_mm,
        hold_min_support=c.junction_hold_min_support,
        x_min_mm=150.0,
        crossing_zone=(110.0, 162.0),
        keep_clear=c.junction_keep_clear,
        confirm_min=c.junction_confirm_min,
        bar_slope=bar_slope,
    )


def _drive(pos, th, track, delta):
    """The robot advances 1.5 mm and turns δ rad; the tracker is told (odometry)."""
    d = 1.5
    pos = pos + d * np.array([math.cos(th), math.sin(th)])
    track.move(d, delta)
    return pos, th + delta


def _bar_x(pos, th, u, y_s):
    """x_r where the bar (through the world origin along u) meets the stripe y_r = y_s,
    the robot at `pos` heading `th`."""
    c, s = math.cos(th), math.sin(th)
    p = np.array([[c, s], [-s, c]]) @ (-pos)
    v = np.array([[c, s], [-s, c]]) @ u
    return p[0] + v[0] * (y_s - p[1]) / v[1]


def _approach(bar_deg: float, bar_slope: bool, noise: float = 0.5) -> np.ndarray:
    """|reported − true| x_r (mm) per frame of a robot turning 0.25° a frame while it
    advances 1.5 mm towards a bar at `bar_deg` to its path; the vertical stripe at
    y_r = −39 mm sees the bar's centre line with `noise` mm of scatter."""
    rng = np.random.default_rng(3)
    track = _track(bar_slope)
    y_s = -39.0
    u = np.array([math.cos(math.radians(bar_deg)), math.sin(math.radians(bar_deg))])
    pos, th, errors = np.array([-200.0, 0.0]), 0.0, []
    for i in range(40):
        if i:
            pos, th = _drive(pos, th, track, math.radians(0.25))
        x_true = _bar_x(pos, th, u, y_s)
        x = x_true + noise * rng.standard_normal()
        xj = track.update(i, x, (96.5, 219.5), y_s, (y_s, 0.0))
        if math.isfinite(xj):
            errors.append(abs(xj - x_true))
    return np.array(errors)


def test_oblique_bar_followed_while_turning():
    # 60°: without the bar's slope the held median falls behind the sightings (8.6 mm after
    # 7° of turn, then out of tolerance of them: the report lapses); with it 0.35 mm on
    # average, 2.0 mm at most (the median's lag before 10 sightings show a significant
    # slope; bound 2.5 mm, under the 3 mm)
    plain, sloped = _approach(60.0, False), _approach(60.0, True)
    assert plain.max() > 5.0
    assert len(sloped) >= 36
    assert sloped.max() < 2.5
    assert sloped.mean() < 0.5


def test_square_bar_with_slope():
    # 90°: in the robot frame the bar turns with the robot (10° over the run); the median
    # lags ≈ 2 mm by the end (0.8 mm mean), the line through the plate points stays within
    # the scatter (0.5 mm)
    plain, sloped = _approach(90.0, False), _approach(90.0, True)
    assert len(sloped) == len(plain) >= 36
    assert sloped.max() < 1.5
    assert sloped.mean() < plain.mean()


def _profile(beads) -> tuple[np.ndarray, np.ndarray]:
    """(640, 3) horizontal-stripe points on a plate at x_r 150 mm with circular-cap beads
    (centre y_r, width, height) mm, 0.03 mm noise."""
    y = np.linspace(-80.0, 80.0, 640)
    z = np.zeros_like(y)
    for yc, w, h in beads:
        rho = (w * w / 4 + h * h) / (2 * h)
        d2 = (y - yc) ** 2
        z = np.maximum(
            z, np.where(d2 < w * w / 4, np.sqrt(np.maximum(rho**2 - d2, 0)) - (rho - h), 0)
        )
    z = z + 0.03 * np.random.default_rng(0).standard_normal(y.shape)
    return np.stack([np.full_like(y, 150.0), y, z], 1), np.ones(640, bool)


@pytest.mark.parametrize("offset", [-6.0, 3.0])
def test_bead_near_prediction_not_the_larger_bar(offset):
    # the stem (15 mm wide) at `offset`, an oblique bar's 30 mm run 25 mm to its left
    P, valid = _profile([(offset, 15.0, 2.0), (offset + 25.0 + 7.5, 30.0, 2.2)])
    cfg = WeldConfig()
    # no point left out: the largest run, as the pipeline's `stripe_feature` takes it
    largest = bead_near(P, offset + 0.8, 0.0, 150.0, 1e3, cfg)
    assert abs(float(largest.position) - (offset + 32.5)) < 1.0
    near = bead_near(P, offset + 0.8, 0.0, 150.0, 7.5 + 8.0, cfg)
    assert bool(near.found)
    assert abs(float(near.position) - offset) < 0.2
    assert abs(float(near.width) - 15.0) < 1.0
    assert abs(float(near.height) - 2.0) < 0.2


def test_tracker_compiles_bead_near_at_start_up():
    """The program the tracker builds when it starts (`near_program`, the tracker's key) finds
    the stem, not the larger bar, from float32 points: no compile waits for a gated frame."""
    from cslx.runtime.bead_near import _PROGRAMS, near_program
    from cslx.runtime.pipeline_config import tracking_config

    P, _ = _profile([(3.0, 15.0, 2.0), (3.0 + 32.5, 30.0, 2.2)])
    near = near_program(lambda: tracking_config().weld, "tracking_config().weld", 640)
    assert _PROGRAMS[("tracking_config().weld", 640)] is near
    line = (3.8, 0.0, 150.0, 7.5 + 8.0)
    f = near(P.astype(np.float32), *(np.float32(v) for v in line))
    assert bool(f.found)
    assert abs(float(f.position) - 3.0) < 0.2
    assert abs(float(f.width) - 15.0) < 1.0


def _entering(bar_deg: float, **overrides) -> np.ndarray:
    """|reported − true| x_r (mm) on the frames a bar at `bar_deg` is in view: the robot
    turns 0.5° a frame while it advances 1.5 mm, and the bar enters the far end of the view
    only 9 frames before the end of the run (issue 12, T at 120°, fresh seed 7400: too few
    sightings for the 10-point line); NaN where no T is reported."""
    rng = np.random.default_rng(3)
    track = JunctionTrack.from_config(KalmanConfig(), 150.0, **overrides)
    y_s = -39.0
    u = np.array([math.cos(math.radians(bar_deg)), math.sin(math.radians(bar_deg))])
    pos, th, errors = np.array([-235.0, 0.0]), 0.0, []
    for i in range(40):
        if i:
            pos, th = _drive(pos, th, track, math.radians(0.5))
        x_true = _bar_x(pos, th, u, y_s)
        seen = i >= 31
        x = x_true + 0.5 * rng.standard_normal() if seen else None
        # the view's far end just short of the bar until it enters
        xj = track.update(i, x, (96.5, x_true + (3.0 if seen else -3.0)), y_s, (y_s, 0.0))
        if seen:
            errors.append(abs(xj - x_true))
    return np.array(errors)


def test_oblique_bar_followed_from_its_first_sightings():
    # 60°, 9 sightings: the 10-point line never comes, the median falls 3.5–6.0 mm behind
    # from the 3rd report on; with the oblique bar's line from 6 points (the default) within
    # 0.9 mm from the 6th sighting on
    before = _entering(60.0, bar_oblique_points=None)
    after = _entering(60.0)
    assert np.nanmax(before[5:]) > 3.0
    assert np.all(np.isfinite(after[2:]))
    assert after[5:].max() < 1.0


def test_square_bar_entering_keeps_the_median():
    # 90°: the slope of a square bar's few points stays under 15° / 3σ, the report is the
    # median's, bit for bit
    assert np.array_equal(_entering(90.0), _entering(90.0, bar_oblique_points=None), True)


def test_few_points_on_a_slope_that_misses_the_newest():
    # dev seed 7326 beside sunny: 6–9 sightings of a square bar entering the view lay on a
    # slope k 0.65 ± 0.13 (beyond 3σ, 33° from square) but the newest lay 2.6–4.2 mm off
    # that line, nearer their median: the median is kept
    track = JunctionTrack.from_config(KalmanConfig(), 150.0)
    track.stripe_line = (-39.0, 0.0)
    ys = np.array([-41.0, -40.0, -39.0, -38.0, -37.0, -36.0])
    xs = 200.0 + 0.65 * (ys + 39.0)
    for newest, expected in ((200.3, math.nan), (201.9, 200.0)):
        # off the line (201.95), near the median (200.3); then on it: the line at y_s
        xs[-1] = newest
        track.points = {f: (float(xs[f]), float(ys[f])) for f in range(6)}
        x = track._on_bar(list(range(6)))
        assert math.isnan(x) if math.isnan(expected) else abs(x - expected) < 0.5
