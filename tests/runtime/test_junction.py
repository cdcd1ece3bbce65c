"""The crossing weld of a T on the vertical stripe (cslx.runtime.junction) and the bead's
position from the cap model where part of the bead is missing (cslx.runtime.weld)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.runtime import junction
from cslx.runtime.junction import crossing_feature
from cslx.runtime.weld import WeldConfig, stripe_feature

PLATE = dict(z0=0.7, gx=0.03, gy=-0.045)  # a tilted, offset plate (as in test_weld.py)


def _plate_z(x, y, plate):
    return plate["z0"] + plate["gx"] * x + plate["gy"] * y


def _bead_height(d, width, height):
    """Circular-arc bead cross-section at signed distance d from the weld centre line."""
    R = (width**2 / 4 + height**2) / (2 * height)
    return np.where(np.abs(d) < width / 2, np.sqrt(np.maximum(R**2 - d**2, 0)) - (R - height), 0.0)


crossing = jax.jit(crossing_feature)
feature = jax.jit(stripe_feature, static_argnums=(2, 3))


def vertical_stripe(rng, *, bar_x=None, bar=(14.0, 2.0), flank=None, noise=0.04, n=480):
    """The vertical stripe along x_r (row order: x decreasing, like the default rig).

    bar_x: x_r of a crossing weld (width, height = bar) or None; flank: None for bare plate
    beside the followed weld, or (h0, h1) — the followed bead's flank under the stripe, its
    height going linearly from h0 at the near end to h1 at the bar (the heading moves the
    stripe across the flank), ending where the bar is (the stem ends at the bar).
    """
    x = np.linspace(218.0, 97.0, n)
    y = -40.0 - 0.0637 * (x - 150.0)
    z = _plate_z(x, y, PLATE)
    h = np.zeros(n)
    if flank is not None:
        h0, h1 = flank
        end = bar_x if bar_x is not None else np.inf
        f = h0 + (h1 - h0) * (x - x.min()) / ((bar_x or x.max()) - x.min())
        h = np.where(x < end, f, 0.0)
    if bar_x is not None:
        h = np.maximum(h, _bead_height(x - bar_x, *bar))
    pts = np.stack([x, y, z + h + rng.normal(0, noise, n)], -1)
    return pts, rng.random(n) > 0.05


@pytest.mark.parametrize(
    "bar_x,bar,flank",
    [
        (190.0, (14.0, 2.0), None),  # beside the weld, bare plate
        (130.0, (20.0, 1.6), None),
        (175.0, (14.0, 2.2), (1.0, 1.4)),  # along the followed bead's flank
        (160.0, (16.0, 2.4), (0.2, 1.6)),  # the flank rising towards the bar
        (200.0, (12.0, 2.0), (1.2, 0.6)),
    ],
)
def test_crossing_found_for_both_placements(bar_x, bar, flank):
    """Within 1 mm of the true x_r (the tracker's tolerance is 3 mm), in every placement."""
    rng = np.random.default_rng([int(bar_x), int(10 * bar[0])])
    pts, valid = vertical_stripe(rng, bar_x=bar_x, bar=bar, flank=flank)
    f = crossing(jnp.asarray(pts), jnp.asarray(valid), WeldConfig())
    assert bool(f.found)
    assert abs(float(f.position) - bar_x) < 1.0, float(f.position)
    assert float(f.confidence) > 0.1


@pytest.mark.parametrize(
    "flank",
    [None, (1.5, 1.5), (1.8, 0.0), (0.0, 1.8)],  # bare plate; a flank, level or sliding
)
def test_no_crossing_no_report(flank):
    """No bar: bare plate, or a flank that the stripe leaves or climbs slowly."""
    rng = np.random.default_rng(7)
    pts, valid = vertical_stripe(rng, flank=flank)
    if flank is not None:  # the flank covers the whole stripe, then slides off to the plate
        x = pts[:, 0]
        h = np.interp(x, [97.0, 218.0], flank)
        pts[:, 2] = _plate_z(x, pts[:, 1], PLATE) + h + rng.normal(0, 0.04, len(x))
    f = crossing(jnp.asarray(pts), jnp.asarray(valid), WeldConfig())
    assert not bool(f.found), float(f.position)


def test_cap_model_with_one_flank_missing():
    """A glint that hides the crown and one flank down to near the toe: the cap model,
    fitted to the bead and the plate around it, still centres the bead within 0.3 mm."""
    rng = np.random.default_rng(11)
    y = np.linspace(80.0, -80.0, 640)
    x = np.full_like(y, 150.0)
    z = _plate_z(x, y, PLATE) + _bead_height(y - 4.0, 16.0, 2.0) + rng.normal(0, 0.04, 640)
    pts = np.stack([x, y, z], -1)
    valid = rng.random(640) > 0.05
    hidden = (y > 4.5) & (y < 11.0)  # the crown and one flank, down to near the toe
    valid = valid & ~hidden
    cap = feature(jnp.asarray(pts), jnp.asarray(valid), 1, WeldConfig(centre="cap"))
    assert bool(cap.found)
    assert abs(float(cap.position) - 4.0) < 0.3, float(cap.position)


def test_crossing_vmap_and_gradients_finite():
    rng = np.random.default_rng(3)
    a, va = vertical_stripe(rng, bar_x=180.0)
    b, vb = vertical_stripe(rng, bar_x=150.0, flank=(1.0, 1.2))
    P, V = jnp.asarray(np.stack([a, b])), jnp.asarray(np.stack([va, vb]))
    batch = jax.jit(jax.vmap(crossing_feature, in_axes=(0, 0, None)))(P, V, WeldConfig())
    one = crossing(P[1], V[1], WeldConfig())
    assert float(batch.position[1]) == pytest.approx(float(one.position), abs=1e-6)
    g = jax.jit(jax.grad(lambda p: crossing_feature(p, V[0], WeldConfig()).position))(P[0])
    assert np.all(np.isfinite(np.asarray(g)))


def _toes(points, valid, config):
    """How many run ends `crossing_feature` tests (its toe rule, in NumPy)."""
    x, z = points[valid, 0], points[valid, 2]
    o = np.argsort(x)
    x, z = x[o], z[o]
    h = z - np.polyval(np.polyfit(x, z, 1), x)
    low = np.array([h[(x >= xi) & (x <= xi + config.crossing_background_mm)].min() for xi in x])
    above = (h - low) > config.threshold_mm
    return int(np.sum(above[:-1] & ~above[1:]))


@pytest.mark.parametrize("bumps", [0, 40])
def test_apex_tests_on_the_first_toes_equal_every_point(monkeypatch, bumps):
    """The apex tests on the first MAX_TOES toes give the values of the tests on every point,
    and a profile with more toes than that takes the tests on every point (lax.cond)."""
    rng = np.random.default_rng(5)
    pts, valid = vertical_stripe(rng, bar_x=170.0)
    if bumps:  # narrow bumps all along the stripe: many toes
        x = pts[:, 0]
        pts[:, 2] += 0.6 * (np.cos(2 * np.pi * x / (121.0 / bumps)) > 0.6)
    config = WeldConfig()
    n_toes = _toes(pts, valid, config)
    assert (n_toes > junction.MAX_TOES) == bool(bumps), n_toes
    P, V = jnp.asarray(pts), jnp.asarray(valid)
    short = jax.jit(crossing_feature)(P, V, config)
    monkeypatch.setattr(junction, "MAX_TOES", pts.shape[0])  # every point, as before
    every = jax.jit(crossing_feature)(P, V, config)
    for a, b in zip(short, every, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    if not bumps:
        assert bool(short.found)


@pytest.mark.parametrize("case", ["short", "wide", "unsorted", "few"])
def test_far_side_band_equals_every_point(monkeypatch, case):
    """The lowest point beyond each one, searched among the FAR_BAND points after it (t rising
    and the band reaching past the window), equals the search over every point; a window
    wider than the band ("wide"), t not rising ("unsorted") and a profile shorter than the
    band ("few") take the full search (lax.cond) and give the same values too."""
    rng = np.random.default_rng(11)
    n = 40 if case == "few" else 480
    t = np.cumsum(rng.uniform(0.1, 0.4, n)).astype(np.float32)
    if case == "unsorted":
        t[100], t[101] = t[101], t[100]
    h = rng.normal(0.0, 1.0, n).astype(np.float32)
    ok = rng.random(n) > 0.1
    width = jnp.float32(40.0 if case == "wide" else 12.0)
    args = (jnp.asarray(t), jnp.asarray(h), jnp.asarray(ok), width)
    band = jax.jit(junction._above_far_side)(*args)
    size = junction.FAR_BAND
    monkeypatch.setattr(junction, "FAR_BAND", 10**6)  # every point, as before
    every = jax.jit(junction._above_far_side)(*args)
    for a, b in zip(band, every, strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    if case == "short":  # the band's own search gives these values
        low = junction._far_low(*args[:3], width, size)
        np.testing.assert_array_equal(
            np.asarray(jnp.where(jnp.asarray(ok) & jnp.isfinite(low), low, 0.0)),
            np.asarray(every[1]),
        )


def _flank_to_bar(rng, bar_x, hi, lo, bar=(14.0, 1.9), n=480):
    """The vertical stripe on the followed bead's flank from x_r = 125 mm up to the bar's near
    toe, the flank's height going from `hi` (at 150 mm) to `lo` (at the toe); plate beyond."""
    x = np.linspace(218.0, 97.0, n)
    y = -40.0 - 0.0637 * (x - 150.0)
    toe = bar_x - 0.5 * bar[0]
    f = np.clip((x - 120.0) / 10.0, 0.0, 1.0) * np.interp(x, [150.0, toe], [hi, lo])
    h = np.maximum(np.where(x < toe, f, 0.0), _bead_height(x - bar_x, *bar))
    pts = np.stack([x, y, _plate_z(x, y, PLATE) + h + rng.normal(0, 0.04, n)], -1)
    return pts, rng.random(n) > 0.05


@pytest.mark.parametrize(
    "bar_x,hi,lo",
    [(205.0, 2.0, 0.8), (209.0, 1.8, 1.0), (203.0, 2.0, 0.4), (180.0, 1.6, 1.6)],
)
def test_crossing_on_a_flank_measured_against_the_plate_beyond(bar_x, hi, lo):
    """Most of the stripe on the flank, the bar just entering the view (issue 12, dev seed
    1202): its height is measured against the plate past its far toe, so it reaches the
    tracker's 1 mm minimum; against one plate line through the flank it did not."""
    rng = np.random.default_rng([int(bar_x), int(10 * hi), int(10 * lo)])
    pts, valid = _flank_to_bar(rng, bar_x, hi, lo)
    f = crossing(jnp.asarray(pts), jnp.asarray(valid), WeldConfig())
    assert bool(f.found)
    assert abs(float(f.position) - bar_x) < 1.0, float(f.position)
    assert abs(float(f.height) - 1.9) < 0.3, float(f.height)
    old = crossing(jnp.asarray(pts), jnp.asarray(valid), WeldConfig(crossing_background_mm=0.0))
    assert not (bool(old.found) and float(old.height) >= 1.0) or lo == hi


def _run_off(rng, rate=0.21, bar_x=None, bar=(14.0, 2.0), noise=0.1, n=480):
    """The vertical stripe crossing the followed bead (15 × 2 mm, centred at x_r = 175 mm)
    at a shallow angle: `rate` mm across the bead per mm along x_r (0.21 on the rendered
    ``cross_toe`` approach, fresh seed 7400, frame 7), so that it climbs the near flank, runs
    over the crown and off the far flank onto the plate over ≈ 35 mm; with `bar_x`, the stem
    ends at a crossing weld there."""
    x = np.linspace(218.0, 97.0, n)
    y = -40.0 - 0.0637 * (x - 150.0)
    h = _bead_height(rate * (x - 175.0), 15.0, 2.0)
    if bar_x is not None:
        h = np.maximum(np.where(x < bar_x, h, 0.0), _bead_height(x - bar_x, *bar))
    pts = np.stack([x, y, _plate_z(x, y, PLATE) + h + rng.normal(0, noise, n)], -1)
    return pts, rng.random(n) > 0.05


def test_run_off_the_flank_is_no_crossing():
    """Where the stripe runs off the followed bead's flank onto the plate, heights above the
    plate beyond make a bump that passed the apex tests (issue 12: 7 / 12 false T frames on
    the rendered ``cross_toe`` approach, clean / sunny, fresh seed 7400); the ramp test
    (`WeldConfig.crossing_ramp_max`) rejects it: the plate-line height one background length
    before its apex is higher than the apex."""
    config = WeldConfig()  # the tracker's differs only in fields the detector does not use
    off = dataclasses.replace(config, crossing_ramp_max=float("inf"))
    seen = seen_before = 0
    for seed in range(6):
        pts, valid = _run_off(np.random.default_rng([seed, 21]))
        for cfg, is_new in ((config, True), (off, False)):
            f = crossing(jnp.asarray(pts), jnp.asarray(valid), cfg)
            tall = bool(f.found) and float(f.height) >= 1.0  # the tracker's minimum height
            if is_new:
                seen += tall
            else:
                seen_before += tall
    assert seen == 0
    assert seen_before >= 3  # without the ramp test the run-off passes for a crossing weld


@pytest.mark.parametrize("bar_x", [200.0, 206.0])
def test_bar_beyond_a_run_off_still_found(bar_x):
    """The crossing weld just past the run-off (the stem ends at it) is still found, in place."""
    pts, valid = _run_off(np.random.default_rng([int(bar_x), 5]), bar_x=bar_x, noise=0.05)
    f = crossing(jnp.asarray(pts), jnp.asarray(valid), WeldConfig())
    assert bool(f.found) and float(f.height) >= 1.0
    assert abs(float(f.position) - bar_x) < 1.0, float(f.position)


@pytest.mark.parametrize("case", ["rising", "falling", "unsorted", "none_valid"])
@pytest.mark.parametrize("one_call", [False, True])
def test_sort_free_order_equals_argsort(case, one_call):
    """`_x_order` (no sort where the valid keys are monotone) is the stable `jnp.argsort`."""
    rng = np.random.default_rng(17)
    x = np.cumsum(rng.uniform(0.1, 0.4, 480)).astype(np.float32)
    if case == "falling":
        x = x[::-1].copy()
    if case == "unsorted":
        x[100], x[101] = x[101], x[100]
    valid = rng.random(480) > (1.0 if case == "none_valid" else 0.2)
    key = jnp.where(jnp.asarray(valid), jnp.asarray(x), jnp.inf)
    got = jax.jit(junction._x_order, static_argnums=2)(key, jnp.asarray(valid), one_call)
    np.testing.assert_array_equal(np.asarray(got), np.asarray(jnp.argsort(key)))


def test_crossing_as_one_function_equals_plain_call():
    """`crossing_feature(..., one_call=True)` (one compiled function, no sort) equals the plain
    call bit for bit, rows in either order."""
    rng = np.random.default_rng(4)
    for bar_x, flank in ((170.0, None), (150.0, (1.0, 1.2))):
        pts, valid = vertical_stripe(rng, bar_x=bar_x, flank=flank)
        for P, V in ((pts, valid), (pts[::-1], valid[::-1])):
            P, V = jnp.asarray(P), jnp.asarray(V)
            plain = jax.jit(crossing_feature)(P, V, WeldConfig())
            one = jax.jit(lambda p, v: crossing_feature(p, v, WeldConfig(), one_call=True))(P, V)
            for a, b in zip(plain, one, strict=True):
                np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
