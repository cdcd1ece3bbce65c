"""The heading from the recent path (`PathHeading`) with the weld-line filter."""

import math

import numpy as np
import pytest

from cslx.runtime.line_filter import KalmanConfig, WeldLineFilter, robust_line
from cslx.runtime.path_heading import PathHeading

X_REF = 150.0
THETA = math.radians(1.1)


def _settle(seed: int = 3):
    """A filter and its path window after 40 accepted beads along a weld at 1.1°, ten of
    them (frames 20–29) biased so that they alone lie on a line 2.2° steeper (a glint's
    bias that drifts); then 20 frames (30 mm) without a bead, as along the bar of a T: the
    window keeps frames 20–39, half of them biased."""
    rng = np.random.default_rng(seed)
    c = KalmanConfig()
    kf, path = WeldLineFilter(c, X_REF), PathHeading(c, X_REF)
    travelled = 0.0
    for k in range(40):
        if k:
            kf.predict(1.5, 0.0)
            path.move(1.5, 0.0)
            travelled += 1.5
        bias = 2.0 * math.tan(THETA) * 1.5 * (k - 30) if 20 <= k < 30 else 0.0
        y = math.tan(THETA) * travelled + bias + rng.normal(0.0, 0.05)
        ok = kf.update(X_REF, y, 0.6)
        path.update(kf, X_REF, y, 0.6, 14.0, ok)
    for _ in range(20):
        kf.predict(1.5, 0.0)
        path.move(1.5, 0.0)
        travelled += 1.5
    return kf, path, travelled


def test_a_rejected_bead_does_not_fuse_the_stale_window():
    """After coasting, a bead the gate rejects leaves the filter as it was: the window of
    old centres (here biased) is not fused (with the old rule the heading went ≈ 1° off)."""
    kf, path, travelled = _settle()
    x0, p0 = kf.x.copy(), kf.P.copy()
    assert abs(math.degrees(kf.x[1] - THETA)) < 0.2
    h = path.points  # the stale window alone is well off, and coasting broadened the filter
    _, th_window, _ = robust_line(h[:, 0], h[:, 1], h[:, 2], X_REF, 0.15, 3.0)
    assert abs(math.degrees(th_window - THETA)) > 0.5
    assert math.degrees(math.sqrt(kf.P[1, 1])) > 2.0
    ok = kf.update(X_REF, -43.0, 0.05)  # a bead on the crossing weld, far off
    assert not ok
    th, sd = path.update(kf, X_REF, -43.0, 0.05, 14.0, ok)
    assert abs(math.degrees(kf.x[1] - THETA)) < 0.2  # the old rule: 2.19°, 1.09° off
    np.testing.assert_array_equal(kf.x, x0)
    np.testing.assert_array_equal(kf.P, p0)
    assert math.isnan(th) and math.isnan(sd)
    # the window still holds the old centres, and an accepted bead fuses it again
    y = math.tan(THETA) * travelled
    ok = kf.update(X_REF, y, 0.6)
    assert ok
    th, _ = path.update(kf, X_REF, y, 0.6, 14.0, ok)
    assert math.isfinite(th)


def test_restart_forgets_the_window():
    kf, path, _ = _settle()
    assert len(path.points) > 6
    kf.start(5.0)
    kf.restarts += 1
    path.update(kf, X_REF, 5.0, 0.6, 14.0, True)
    assert len(path.points) == 1


def _heading_z(gain_only: bool, draws: int = 150, frames: int = 25) -> np.ndarray:
    """(heading error / the filter's heading sd) on frames 10–24 of straight passes at a random
    heading within ±3.5°, one bead a frame (1.5 mm apart) with the noise the filter assumes
    (`sigma_meas` at confidence 1): the window's first 15–36 mm, where it is noisiest."""
    import dataclasses

    c = dataclasses.replace(KalmanConfig(), heading_gain_only=gain_only)
    z = []
    for s in range(draws):
        rng = np.random.default_rng(s)
        th, y0 = math.radians(rng.uniform(-3.5, 3.5)), rng.uniform(-3.0, 3.0)
        kf, path = WeldLineFilter(c, X_REF), PathHeading(c, X_REF)
        for k in range(frames):
            if k:
                kf.predict(1.5, 0.0)
                path.move(1.5, 0.0)
            y = y0 + math.tan(th) * 1.5 * k + rng.normal(0.0, c.sigma_meas)
            ok = kf.update(X_REF, y, 1.0)
            path.update(kf, X_REF, y, 1.0, 14.0, ok)
            if k >= 10:
                z.append((kf.x[1] - th) / math.sqrt(kf.P[1, 1]))
    return np.asarray(z)


def test_window_heading_sd_covers_the_error():
    """Fusing only the information the window gained (`heading_gain_only`) leaves a heading
    sd that covers the error (RMS of error / sd 1.21 from a 15 mm span); fused as a new
    independent measurement every frame (the default) the window's shared centres are counted
    again and again and
    the sd is too small (RMS 1.83 with the window fused from 15 mm of span, 1.42 from the
    default 22 mm; gain-only 0.98 there)."""
    rms = {m: float(np.sqrt(np.mean(_heading_z(m) ** 2))) for m in (False, True)}
    assert rms[False] > 1.25, rms
    assert 0.8 < rms[True] < 1.15, rms


def test_predicted_sd_is_the_weighted_slope_sd():
    """`predicted_sd` against the spread of weighted least-squares slopes over noise draws
    with variance sigma² / w per point (the measurement model of `WeldLineFilter.update`)."""
    from cslx.runtime.path_heading import predicted_sd

    rng = np.random.default_rng(0)
    x = np.arange(12) * 1.5 + 140.0
    w = rng.uniform(0.2, 1.0, x.size)
    sigma = 0.35
    slopes = []
    for _ in range(4000):
        y = 0.02 * x + rng.normal(0.0, sigma / np.sqrt(w))
        xm, ym = (w @ x) / w.sum(), (w @ y) / w.sum()
        slopes.append((w @ ((x - xm) * (y - ym))) / (w @ (x - xm) ** 2))
    sd = predicted_sd(x, w, sigma)
    assert abs(np.std(slopes) / sd - 1.0) < 0.05
    assert predicted_sd(np.full(5, 150.0), np.ones(5), sigma) == math.inf


def _first_fused(confidence: float, **kw) -> float:
    """Travel (mm) at which the window's heading is first fused on a straight pass, one bead
    a frame 1.5 mm apart, each with this confidence."""
    import dataclasses

    c = dataclasses.replace(KalmanConfig(), **kw)
    for k, th, _ in _straight_pass(c, confidence, seed=1):
        if math.isfinite(th):
            return 1.5 * k
    return math.inf


def _straight_pass(c: KalmanConfig, confidence: float, seed: int):
    """A straight pass of 60 frames, one bead a frame 1.5 mm apart (0.05 mm noise), each with
    this confidence, through a filter and its path window: yields (frame, window heading,
    the window) after each frame's update."""
    rng = np.random.default_rng(seed)
    kf, path = WeldLineFilter(c, X_REF), PathHeading(c, X_REF)
    for k in range(60):
        if k:
            kf.predict(1.5, 0.0)
            path.move(1.5, 0.0)
        y = math.tan(THETA) * 1.5 * k + rng.normal(0.0, 0.05)
        ok = kf.update(X_REF, y, confidence)
        th, _ = path.update(kf, X_REF, y, confidence, 14.0, ok)
        yield k, th, path


def test_max_sd_sets_the_span_by_confidence():
    """With `heading_max_sd_deg` the window waits for a longer span when its centres are less
    certain; with the fixed span alone it does not."""
    assert _first_fused(0.9) == _first_fused(0.2) == 22.5  # 15 centres, 1.5 mm apart
    kw = dict(heading_min_span_mm=6.0, heading_max_sd_deg=1.2)
    hi, lo = _first_fused(0.9, **kw), _first_fused(0.2, **kw)
    assert 6.0 <= hi < lo < math.inf, (hi, lo)


def test_sd_model_floors_the_fused_sd():
    """`heading_sd_model`: the sd returned (and fused) is at least the model's prediction,
    although the centres here lie almost exactly on a line (residual sd tiny)."""
    import dataclasses

    from cslx.runtime.path_heading import predicted_sd

    c = dataclasses.replace(KalmanConfig(), heading_sd_model=True)
    kf, path = WeldLineFilter(c, X_REF), PathHeading(c, X_REF)
    for k in range(20):
        if k:
            kf.predict(1.5, 0.0)
            path.move(1.5, 0.0)
        y = math.tan(THETA) * 1.5 * k
        ok = kf.update(X_REF, y, 0.5)
        th, sd = path.update(kf, X_REF, y, 0.5, 14.0, ok)
    h = path.points
    want = math.degrees(predicted_sd(h[:, 0], h[:, 2], c.sigma_meas))
    assert math.isfinite(th) and sd == pytest.approx(want)


def _reported_from(confidence: float, valid_deg: float = 0.8) -> float:
    """Travel (mm) at which the window's model sd (`PathHeading.model_var`, which the
    tracker reports as the heading's uncertainty and requires below
    `KalmanConfig.heading_valid_deg`) first falls below `valid_deg` on a straight pass,
    one bead a frame 1.5 mm apart, each with this confidence."""
    from cslx.runtime.path_heading import predicted_sd

    c = KalmanConfig()
    for k, th, path in _straight_pass(c, confidence, seed=2):
        if math.isfinite(th):  # fused: the model sd is the fused window's prediction
            h = path.points
            want = predicted_sd(h[:, 0], h[:, 2], c.sigma_meas)
            assert path.model_var == pytest.approx(want**2, rel=1e-9)
        if math.degrees(math.sqrt(path.model_var)) < valid_deg:
            return 1.5 * k
    return math.inf


def test_model_sd_waits_longer_for_less_confident_beads():
    """The reported heading's uncertainty follows the centres' confidence: beads of
    confidence 0.2 need a longer stretch of path than beads of 0.9 before the window's
    heading is known to 0.8°, while the fused window (22 mm span) starts at the same frame;
    the window's own residual sd, scale-free in the weights, cannot tell them apart."""
    hi, lo = _reported_from(0.9), _reported_from(0.2)
    assert 22.5 <= hi < lo < math.inf, (hi, lo)
    assert _first_fused(0.9) == _first_fused(0.2)


def test_model_sd_grows_with_travel_and_restarts_forget_it():
    """Without beads the reported model variance grows by q_heading² per mm (the filter's
    random walk); a restart forgets it."""
    c = KalmanConfig()
    kf, path = WeldLineFilter(c, X_REF), PathHeading(c, X_REF)
    for k in range(30):
        if k:
            kf.predict(1.5, 0.0)
            path.move(1.5, 0.0)
        ok = kf.update(X_REF, math.tan(THETA) * 1.5 * k, 0.6)
        path.update(kf, X_REF, math.tan(THETA) * 1.5 * k, 0.6, 14.0, ok)
    var = path.model_var
    assert math.isfinite(var)
    path.move(30.0, 0.0)
    assert path.model_var == pytest.approx(var + c.q_heading**2 * 30.0)
    kf.restarts += 1  # a re-acquisition
    path.update(kf, X_REF, 0.0, 0.6, 14.0, False)
    assert path.model_var == math.inf
