"""The run-off test of `cslx.runtime.junction` (issue 12): the vertical stripe leaving the
followed bead's flank onto the plate is not the crossing weld beyond it."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from cslx.runtime.junction import crossing_feature
from cslx.runtime.weld import WeldConfig

crossing = jax.jit(crossing_feature)
OFF = dict(crossing_bump_mm=float("inf"), crossing_cap_max=float("inf"))
ON = WeldConfig(crossing_bump_mm=1.0, crossing_cap_max=1.0)  # opt-in (junction.py)
PLATE = dict(z0=0.7, gx=0.03, gy=-0.045)  # a tilted, offset plate (as in test_junction.py)


def _plate_z(x, y, plate):
    return plate["z0"] + plate["gx"] * x + plate["gy"] * y


def _bead_height(d, width, height):
    """Circular-arc bead cross-section at signed distance d from the weld centre line."""
    R = (width**2 / 4 + height**2) / (2 * height)
    return np.where(np.abs(d) < width / 2, np.sqrt(np.maximum(R**2 - d**2, 0)) - (R - height), 0.0)


def _flank_run_off(rng, *, bar_x=205.0, bar=(14.0, 2.0), dip=-1.0, n=480):
    """The stripe on the stem's flank (2 mm, with a glare ripple of ±0.3 mm over 9 mm) up to
    x_r = 158 mm, off it onto the plate over 4 mm, a glare dip `dip` mm below the plate 3–7
    mm past it (rendered dev seed 1205, cross on the flank, glare frames 16–17: ripples of
    ±0.3–0.5 mm, dips to −1 mm), and the bar at `bar_x` on the plate."""
    x = np.linspace(218.0, 97.0, n)
    y = -40.0 - 0.0637 * (x - 150.0)
    h = 2.0 * np.clip((162.0 - x) / 4.0, 0.0, 1.0)
    h = h + np.where(x < 162.0, 0.3 * np.sin(2.0 * np.pi * x / 9.0), 0.0)
    h = np.where((x > 165.0) & (x < 169.0), dip, h)
    h = np.maximum(h, _bead_height(x - bar_x, *bar))
    pts = np.stack([x, y, _plate_z(x, y, PLATE) + h + rng.normal(0, 0.05, n)], -1)
    return pts, rng.random(n) > 0.05


def test_bar_beyond_a_run_off_wins_over_it():
    """The run-off, measured against the dip past it, stands higher than the bar and won the
    highest-apex rule; with plate on both sides the bar is preferred (recall 81.8 → 90.9 %
    on 1205 flank glare in replay)."""
    config = ON
    for seed in range(2):
        pts, valid = _flank_run_off(np.random.default_rng([seed, 33]))
        args = (jnp.asarray(pts), jnp.asarray(valid))
        new = crossing(*args, config)
        old = crossing(*args, dataclasses.replace(config, **OFF))
        assert bool(new.found) and abs(float(new.position) - 205.0) < 1.0, float(new.position)
        assert bool(old.found) and float(old.position) < 175.0, float(old.position)


def test_bar_on_the_flank_still_found():
    """No plate before the bar (the stem's flank up to it) and none farther: still found."""
    x = np.linspace(218.0, 97.0, 480)
    y = -40.0 - 0.0637 * (x - 150.0)
    h = np.maximum(np.where(x < 190.0, 1.2, 0.0), _bead_height(x - 190.0, 14.0, 2.0))
    rng = np.random.default_rng(7)
    pts = np.stack([x, y, _plate_z(x, y, PLATE) + h + rng.normal(0, 0.05, 480)], -1)
    f = crossing(jnp.asarray(pts), jnp.asarray(rng.random(480) > 0.05), ON)
    assert bool(f.found) and abs(float(f.position) - 190.0) < 1.0, float(f.position)
