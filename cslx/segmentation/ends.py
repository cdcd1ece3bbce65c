"""The end of a turned stripe inside the frame: the first pass's tail past it (issue 11).

The linked detector's first pass (`cslx.segmentation.ridges`, column profiles) smooths the
image by `SIGMA_ALONG` (6 px) along the image axis, not along the stripe. Where the laser's
fan ends inside the frame, a stripe turned against the axes (slope m across per centre
along) leaves in the columns past its end a smoothed ridge that still reaches high
strength for ≈ 2 σ_along, but whose row stays near the end's row instead of following the
slope: the path ran 10–15 columns past the end (the truth has no stripe there), and the
profiles within a few columns inside the end, which mix the missing part, are pulled towards
the tail. Audit frame (`experiments/ood_extraction.py`, cross turned 35°, sunny, fresh seed
7502 frame 0, horizontal stripe, fan's end at column 50): the first-pass path starts at
column 38 (strength 7 → 104 over 38–49, the plateau ≈ 138) 1.0–1.3 px off the stripe's line
extended there, and is 2.9 / 2.4 / 2.0 / 1.6 px off the truth at columns 50–53; the output
kept 12 false centres and 2 gross (> 1 mm) ones there.

`oblique_ends` trims such a tail geometrically: at each end of the path that is neither at
the image's border along the stripe (the stripe leaves the frame there) nor within `REACH`
px of the border across it (`crossing` handles those ends), the straight line through the
path's centres `REACH` to 3 `REACH` centres inside the end is extended outwards; where it
says the stripe is turned (|slope| ≥ `crossing.MIN_SLOPE`, as for the turned crossing),
the end is cut inside the innermost pair of consecutive centres (within `REACH` of the end)
that both leave that line by more than `TOLERANCE` px or 3 robust std of the path's scatter
about it, whichever is larger (two in a row: one noisy centre on a rough first pass is not a
tail). An aligned stripe's tail lies on its line and is left alone. Evidence: the module
docstring of `experiments/ood_extraction.py`.

Pure JAX, jit-compiled (and traced inside `robust._finish`'s compiled call).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp

from . import crossing

__all__ = ["REACH", "TOLERANCE", "oblique_ends"]

#: Centres (px along the stripe) over which a tail is looked for, and the start of the line's
#: support inside the end: 3 × the first pass's smoothing along the axis (`SIGMA_ALONG` 6 px).
REACH = 18
#: Smallest departure (px) from the line that marks a tail.
TOLERANCE = 1.0


def _trim_start(pos, valid, n_across: int):
    """`valid` with the tail at the path's start (lowest index) dropped (module docstring)."""
    n = pos.shape[0]
    j = jnp.arange(n)
    big = jnp.asarray(n, jnp.int32)
    e = jnp.min(jnp.where(valid, j, big))
    support = valid & (j >= e + REACH) & (j < e + 3 * REACH)
    w = support.astype(pos.dtype)
    x = (j - e).astype(pos.dtype)
    y = jnp.where(support, pos, 0.0)
    sw, sx, sxx = w.sum(), (w * x).sum(), (w * x * x).sum()
    sy, sxy = (w * y).sum(), (w * x * y).sum()
    det = sw * sxx - sx * sx
    ok = (sw >= REACH) & (det > 1e-6)
    safe = jnp.where(ok, det, 1.0)
    b = (sw * sxy - sx * sy) / safe
    a = (sxx * sy - sx * sxy) / safe
    resid = pos - a - b * x
    spread = jnp.where(support, jnp.abs(resid), jnp.inf)
    mad = jnp.sort(spread)[jnp.maximum(sw.astype(jnp.int32) // 2, 0)]
    tol = jnp.maximum(TOLERANCE, 3.0 * 1.4826 * jnp.where(ok, mad, 0.0))
    end_pos = jnp.where(e < n, pos[jnp.clip(e, 0, n - 1)], 0.0)
    turned = jnp.abs(b) >= crossing.MIN_SLOPE
    inner = (end_pos > REACH) & (end_pos < n_across - 1 - REACH) & (e > 0)
    zone = valid & (j >= e) & (j < e + REACH)
    off = zone & (jnp.abs(jnp.nan_to_num(resid, nan=jnp.inf)) > tol)
    # two consecutive centres off the line (the outer one may be a gap's far side: the next
    # valid centre outwards)
    prev = jnp.concatenate([jnp.zeros(1, bool), off[:-1]])
    pair = off & prev
    cut = jnp.max(jnp.where(pair, j, -1))
    trim = ok & turned & inner & (cut >= 0)
    return valid & ~(trim & (j <= cut))


@functools.partial(jax.jit, static_argnames=("n_across",))
def oblique_ends(pos, valid, n_across: int):
    """(N,) `valid` without the first pass's tail past a turned stripe's end inside the frame,
    at either end of the path (module docstring). `pos` (N,) across, `n_across` the image's
    size across the stripe."""
    valid = _trim_start(pos, valid, n_across)
    return _trim_start(pos[::-1], valid[::-1], n_across)[::-1]
