"""The bead's run on one stripe's profile: which points delimit it, and the largest run.

Step 3 of `cslx.runtime.weld` (module docstring there): a bead is a run of points above the
plate, bounded on both sides by plate points. `plate_points` says which points count as
the plate there, `largest_run` picks the run. Fixed-size, jit/vmap-able, no scatter (so
that `cslx.runtime.small_ops.one_function` compiles the bead's fit as one function).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, Bool, Float

    from .weld import WeldConfig

__all__ = ["largest_run", "plate_points", "side_cover", "steep_points"]


def plate_points(
    t: Float[Array, " n"],
    h: Float[Array, " n"],
    valid: Bool[Array, " n"],
    above: Bool[Array, " n"],
    threshold_mm: float,
    min_plate_mm: float,
) -> Bool[Array, " n"]:
    """The points that delimit a bead run: valid points not above the threshold that lie on
    the plate, in a stretch of such points at least ``min_plate_mm`` long (``t``, along the
    plate, from its first to its last point; invalid and rejected points inside a stretch do
    not end it, points above do), or reaching an end of the profile.

    A point more than ``threshold_mm`` below the plate line is not plate (no bead's interior
    and no plate lies there: a stripe centre pulled off its ridge, e.g. where the other
    stripe crosses the bead); like an invalid point it neither joins nor ends a run. A short
    stretch of points at plate height between two parts of a bead (such a centre passing
    through the plate's height) does not end the run either: a bead split there was fitted
    as its larger half, narrow and off-centre by a quarter of its width (issue 12, fresh
    seed 7320 flank sunny: beads 10.2 / 12.2 mm wide for 18.5, 3.5 / 2.4 mm off).

    ``min_plate_mm`` ≤ 0: every valid point not above is plate (no test on its height).
    """
    plate = valid & ~above
    if min_plate_mm <= 0:
        return plate
    n = h.shape[0]
    idx = jnp.arange(n)
    plate = plate & (h >= -threshold_mm)
    last_up = jax.lax.cummax(jnp.where(above, idx, -1))
    next_up = jax.lax.cummin(jnp.where(above, idx, n), reverse=True)
    first_p = jax.lax.cummin(jnp.where(plate, idx, n), reverse=True)
    last_p = jax.lax.cummax(jnp.where(plate, idx, -1))
    i0 = first_p[jnp.clip(last_up + 1, 0, n - 1)]  # the stretch's first plate point
    i1 = last_p[jnp.clip(next_up - 1, 0, n - 1)]  # and its last
    extent = jnp.abs(t[jnp.clip(i1, 0, n - 1)] - t[jnp.clip(i0, 0, n - 1)])
    open_end = (last_up < 0) | (next_up >= n)
    return plate & (open_end | (extent >= min_plate_mm))


def largest_run(h, above, below):
    """(mask, area Σh) of the run of ``above`` points bounded by ``below`` points on both sides
    (step 3 of `cslx.runtime.weld`) with the largest area, the first of equal ones; where
    none has an area > 0, the points above before the first point below (area 0).

    The area of each point's run is C(next point below) − C(last point below) of the
    cumulative area C, rather than a `segment_sum` over the runs, whose scatter keeps
    `one_function` from compiling the bead's fit as one function (issue 13): the same run
    as segment_sum's argmax, its area to float rounding (tests/runtime/test_weld.py).
    """
    n = h.shape[0]
    idx = jnp.arange(n)
    seg = jnp.cumsum(below.astype(jnp.int32))  # runs (and their plate point) by number
    inside = above & (seg >= 1) & (seg < seg[-1])
    C = jnp.cumsum(jnp.where(inside, h, 0.0))
    last = jax.lax.cummax(jnp.where(below, idx, 0))
    after = jax.lax.cummin(jnp.where(below, idx, n - 1), reverse=True)
    area = jnp.where(inside, C[after] - C[last], 0.0)
    top = jnp.argmax(area)
    best = jnp.where(area[top] > 0, seg[top], 0)
    return above & (seg == best), area[top]


def steep_points(t, h, valid, factor, weight):
    """``extra(p)`` for `cslx.runtime.weld._cap_fit`: ``weight`` where a point's slope
    |dh/dt| from its two neighbours (0 where one is missing) exceeds ``factor`` × the slope
    of the cap p = (a, c, H) at its toe, c / (R − H), its steepest, + 0.1; else 1.

    In sun the stripe on the sunlit flank clips and its points end in a gap; the last
    0.5–1.5 mm before the gap rise or dive by up to 1–2 mm, steeper than the cap, and the
    cap's toe follows them (`experiments/bead_refit.py`, dev seed 7302 flank sunny, frame 5:
    +0.36 → +1.63 mm over 0.7 mm, the centre +0.92 mm off; with weight 0.2: +0.13 mm).
    """
    n = t.shape[0]
    idx = jnp.arange(n)
    both = valid & jnp.roll(valid, 1) & jnp.roll(valid, -1) & (idx > 0) & (idx < n - 1)
    dt = jnp.maximum(jnp.abs(jnp.roll(t, -1) - jnp.roll(t, 1)), 1e-3)
    g = jnp.where(both, jnp.abs(jnp.roll(h, -1) - jnp.roll(h, 1)) / dt, 0.0)

    def extra(p):
        c, H = jnp.abs(p[1]) + 1e-3, jnp.abs(p[2]) + 1e-3
        toe = c / jnp.maximum((c * c - H * H) / (2.0 * H), 1e-3)
        return jnp.where(g > factor * toe + 0.1, weight, 1.0)

    return extra


def side_cover(t, valid, weights, t_c, p_cap, half0, config: WeldConfig):
    """(min(L, R) / max(L, R))^p, p = `WeldConfig.side_cover_power` (1 where p = 0 or no
    weights): L, R the share of the valid points with a prior weight > 0 on each side of the
    bead's centre t_c, out to its half-chord plus `cap_margin_mm` (moved here from
    `cslx.runtime.weld`). A bead one of whose flanks and toes the pipeline weighted out
    (weight 0: a shadow edge along the stripe; a clipped core's 0.1 counts as kept) is
    placed by the other flank alone, and its confidence says so."""
    if weights is None or config.side_cover_power == 0:
        return 1.0
    w = (jnp.asarray(weights, t.dtype) > 0).astype(t.dtype)
    half = jnp.where(jnp.isfinite(p_cap[1]), jnp.abs(p_cap[1]), half0) + config.cap_margin_mm
    d = t - t_c
    sides = []
    for side in (d < 0, d >= 0):
        m = (valid & side & (jnp.abs(d) < half)).astype(t.dtype)
        sides.append(jnp.sum(m * w) / jnp.maximum(jnp.sum(m), 1.0))
    lo, hi = jnp.minimum(*sides), jnp.maximum(*sides)
    return jnp.where(hi > 0, lo / jnp.maximum(hi, 1e-6), 0.0) ** config.side_cover_power
