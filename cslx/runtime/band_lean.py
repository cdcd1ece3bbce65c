"""Tracking bands that follow a leaning stripe (issues 12 / 13).

The pipeline's tracking mode (`cslx.runtime.pipeline`) processes a band of ``2·roi_half_h``
rows around the horizontal stripe (all columns) and of ``2·roi_half_w`` columns around the
vertical one. A straight band holds a stripe that leans by less than the band less its two
margins (64 − 2·8 rows over the 640 columns, ≈ 4°). With the cross projector rolled about
the camera axis the stripes lean: 7.5 / 13.9 / 22.9° for the horizontal one at a roll of
8 / 15 / 25° (`experiments.tracking_generality`, ``proj_roll_*``), and every frame ran the
full frame. Here a band that does not fit straight follows the stripe's line instead: the
band of rows starts, in column u, at s(u) = s₀ + b·u (a float; clamped to the frame), a
straight line fitted to the frame's centres (`stripe_line`); likewise the band of columns
in row v. The cut interpolates between whole rows (`cslx.runtime.band_input.sheared_band`),
so the stripe runs straight along the band and Steger's smoothing along it sees no
staircase; the centres are shifted back to frame coordinates by s(u).

A band that fits straight stays straight (``lean`` (0, 0) in the state, the cut and the
program's values as before), so a rig whose stripes do not lean tracks bit for bit as it
did. The state holds ``lean_h`` / ``lean_v`` = (s₀, b); b = 0 means the straight band at
``row0`` / ``col0``.

Band against full-frame centres (`experiments.band_lean_check`, dev seed 7800, 10 frames,
clean, the tracker's `tracking_config`; per stripe |band − full| median / 99th percentile
px where both found a centre): base ran straight bands, 0 / 0 (identical). Sheared,
interpolated: roll 8° h 0.011 / 0.153, v 0 / 0; 15° h 0.018 / 0.324, v 0 / 0.0001; 25° h
0.031 / 0.742, v 0.031 (p99 129: the full frame's stray centres far from the stripe, which
the band cannot see). The rest is where the other stripe crosses (it leans otherwise in the
sheared band) and within 4σ of the frame's ends, where the full frame's reflect padding kinks
the leaning stripe (tests/runtime/test_band_lean.py). Rejected: the start rounded down to
whole rows (a staircase, no interpolation): h 0.177 / 0.471 (8°), 0.229 / 0.472 (15°),
0.249 / 0.907 (25°), v 0.251 at 25°: Steger's smoothing along the stripe averages the
neighbouring columns' offsets of up to one row.

Tracker (`experiments.tracking_generality --seed 7400 --frames 32`, clean, ``roi_lean`` off
→ on in one process; offset mean / max mm, heading mean °, T recall % / false T, frames in
the bands %): base identical per frame (offset, heading, junction; also against the code
before, bit for bit); 8° 0.090 / 0.36, 0.129, 100 / 0, 0 % → 0.088 / 0.36, 0.130, 100 / 0,
96.9 %; 15° 0.084 / 0.57, 0.358, 100 / 0, 0 % → 0.076 / 0.58, 0.281, 100 / 0, 96.9 %; 25°
0.178 / 0.49, 0.217, 100 / 0, 0 % → 0.174 / 0.49, 0.242, 100 / 0, 87.5 % (with the 98 %
rule of the straight band). Median `Tracker.step` at load 7–10 (noisy; the first variant
of a process often ran slower): 47.1 → 23.7, 73.0 → 8.0, 28.2 → 6.9 ms; base 53.9 → 32.2 ms
(its frames take the straight branch, outputs identical: the load, not the change).

The sheared band is taken when 95 % of the valid centres fit it (`PipelineConfig.
roi_lean_fraction`; the straight band keeps 98 %). At 25° the full frame's centres of the
vertical stripe hold 2–2.7 % strays 100–500 px from its line on 7 of 16 frames (dev seed
7800, `tracking_config`, 97.3–97.9 % inside), so after each full frame the 98 % rule sent
the next one to the full frame again; in the bands no such stray can occur. Seed 7400, 32
frames, one process, 98 → 95 %: 25° 0.174 / 0.49, 0.242°, 87.5 % → 0.169 / 0.49, 0.236°,
96.9 % of frames in the bands (T 100 / 0 both); 15° unchanged (0.076 / 0.58, 96.9 %).

Fresh seeds 7800 / 7801 (32 frames, clean, off → on in one process, the 98 % rule; offset
mean / max mm, heading mean °, frames in the bands): base identical per frame; 8° 0.077 /
0.27, 0.111 → 0.075 / 0.26, 0.104, 96.9 % and 0.133 / 0.47, 0.124 → 0.134 / 0.47, 0.112,
96.9 %; 15° 0.103 / 0.34, 0.136 → 0.105 / 0.33, 0.128 and 0.107 / 0.36, 0.133 → 0.113 /
0.36, 0.156, both 96.9 %; 25° 0.139 / 0.52, 0.178 → 0.143 / 0.52, 0.259, 90.6 % and 0.232
/ 0.56, 0.231 → 0.232 / 0.54, 0.298, 96.9 %; T recall and false T unchanged in every run.
With 95 % (one process, 98 → 95 %): 25° 7800 0.143 / 0.52, 0.259°, 90.6 % → 0.150 / 0.58,
0.292°, 96.9 %; 7801 identical (96.9 % either way). Open: at 25° the bands cost heading,
0.02–0.11° over the full frame in all three runs (7400 0.217 → 0.236, 7800 0.178 → 0.292,
7801 0.231 → 0.298; within the 0.5° goal), and 7800's offset max 0.52 → 0.58 mm; not
diagnosed (candidates: the crossing and the frame's ends above, where band and full frame
differ).
"""

from __future__ import annotations

import equinox as eqx
import jax.numpy as jnp
from jax import lax

from .small_ops import masked_median

__all__ = ["band_cut", "lean_allowed", "lean_starts", "next_bands", "stripe_line"]


def lean_allowed(config) -> bool:
    """Whether the bands may follow a leaning stripe: ``roi_lean``, and no domed fill that
    looks at neighbouring columns (``clip_dome_along``: a sheared cut moves them)."""
    along = config.fill_clipped and config.clip_dome > 0 and config.clip_dome_along > 0
    return bool(config.roi_lean) and not along


def lean_starts(lean, n_along: int, n_across: int, size: int):
    """The sheared band's float start per column (row): s₀ + b·u, within [0, n − size − 1]."""
    u = jnp.arange(n_along, dtype=lean.dtype)
    return jnp.clip(lean[0] + lean[1] * u, 0.0, float(n_across - size - 1))


def band_cut(cut, axis: int, start, lean, size: int, shape, allowed: bool):
    """(band, offset): the straight band at ``start`` when ``lean``'s slope is 0 (or
    ``allowed`` is False), else the sheared one; ``offset`` (scalar or per column / row)
    takes band centres to frame coordinates."""
    if not allowed:
        return cut(axis, start, size), start
    n_across, n_along = shape if axis == 0 else shape[::-1]
    starts = lean_starts(lean, n_along, n_across, size)
    band = lax.cond(lean[1] == 0, lambda: cut(axis, start, size), lambda: cut(axis, starts, size))
    offset = jnp.where(lean[1] == 0, start.astype(starts.dtype), starts)
    return band, offset


def stripe_line(pos, valid, half: float):
    """(a, b): the line pos ≈ a + b·u through a stripe's valid centres.

    Least squares, then once more over the centres within ``half`` px of that line (a few
    stray centres, the other stripe or a glint, move the first fit). NaN when fewer than
    two centres.
    """
    u = jnp.arange(pos.shape[0], dtype=pos.dtype)

    def fit(w):
        w = w.astype(pos.dtype)
        n = jnp.sum(w)
        um = jnp.sum(w * u) / n
        y = jnp.where(w > 0, pos, 0.0)
        ym = jnp.sum(w * y) / n
        b = jnp.sum(w * (u - um) * (y - ym)) / jnp.sum(w * (u - um) ** 2)
        return ym - b * um, b

    a, b = fit(valid)
    near = valid & (jnp.abs(pos - (a + b * u)) <= half)
    return fit(near)


def _inside(pos, valid, lo, hi, min_share: float = 0.98):
    return jnp.sum(valid & (pos >= lo) & (pos <= hi)) >= min_share * jnp.sum(valid)


def next_bands(ch, cv, state, config, shape):
    """Centre the bands on this frame's stripes; track only when both fit inside them.

    The straight band (as before): its centre is the median of the valid centres, as
    `masked_median` (bisection on the float keys, equal to `jnp.nanmedian` bit for bit: the
    two sorts of 640 and 480 values cost 0.34 ms of a tracking frame, issue 13; load 6–7).
    Nearly all centres (98 %) must lie inside the new band, away from its edges by
    ``roi_margin`` (a stripe at the image border may touch the band's edge there); stray
    false centres may not. A stripe that does not fit straight gets a sheared band along
    its fitted line (`stripe_line`; module notes) when it fits that one by the same rule.
    """
    height, width = shape
    hh, hw, m = config.roi_half_h, config.roi_half_w, config.roi_margin
    allowed = lean_allowed(config)

    def band(c, half, size, n):
        centre = masked_median(c.pos, c.valid)
        start = jnp.clip(jnp.round(centre).astype(jnp.int32) - half, 0, size - 2 * half)
        lo = jnp.where(start == 0, -jnp.inf, start + m)
        hi = jnp.where(start == size - 2 * half, jnp.inf, start + 2 * half - 1 - m)
        fits = _inside(c.pos, c.valid, lo, hi)
        enough = jnp.sum(c.valid) >= config.min_valid_fraction * n
        zero = jnp.zeros(2, c.pos.dtype)
        if not allowed:
            return start, fits & enough & jnp.isfinite(centre), zero
        a, b = stripe_line(c.pos, c.valid, half - m)
        lean = jnp.stack([a - half, b]).astype(c.pos.dtype)
        s = lean_starts(lean, n, size, 2 * half)
        top = float(size - 2 * half - 1)
        lo = jnp.where(s <= 0, -jnp.inf, s + m)
        hi = jnp.where(s >= top, jnp.inf, s + 2 * half - 1 - m)
        leans = ~fits & jnp.isfinite(a) & jnp.isfinite(b) & (b != 0)
        leans = leans & _inside(c.pos, c.valid, lo, hi, config.roi_lean_fraction)
        ok = (fits | leans) & enough & jnp.isfinite(centre)
        return start, ok, jnp.where(leans, lean, zero)

    row0, ok_h, lean_h = band(ch, hh, height, width)
    col0, ok_v, lean_v = band(cv, hw, width, height)
    tracking = ok_h & ok_v
    row0, col0 = jnp.where(ok_h, row0, state.row0), jnp.where(ok_v, col0, state.col0)
    # a frame without tracking takes straight bands from the first pass (`_first_pass`)
    lean_h, lean_v = (jnp.where(tracking, x, jnp.zeros_like(x)) for x in (lean_h, lean_v))
    return eqx.tree_at(
        lambda s: (s.row0, s.col0, s.tracking, s.lean_h, s.lean_v),
        state,
        (row0, col0, tracking, lean_h, lean_v),
    )
