"""Small fixed-size kernels of the bead fits that XLA's CPU backend runs slowly as library calls.

The weld features (`cslx.runtime.weld`, `cslx.runtime.junction`) solve ≈ 40 tiny normal
equations (2×2, 3×3) and take ≈ 45 medians of a 480–640-point profile per frame, inside
IRLS and Gauss–Newton loops. As `jnp.linalg.solve` (a LAPACK call each) and
`jnp.nanmedian` (a full sort) they cost ≈ 5 ms of a tracking frame; as the elementwise
kernels here they fuse into the loops (issue 13). Same values to float32 rounding
(tests/runtime/test_small_ops.py). Not kept: both stripes' plate fits (13 IRLS steps, a
median each) under one `jax.vmap`, one chain of loops instead of two: the weld features
1.096 → 1.089 ms, the tracker's tracking frame 4.54 → 4.57 ms (600 / 300 interleaved calls,
load 7–9; outputs within 7e-5), so the loops' step count is not what they cost.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import TYPE_CHECKING, Any

import jax
import jax.numpy as jnp
from jax import lax

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, Bool, Float

__all__ = ["masked_median", "one_function", "solve_spd", "window_nanmedian"]


def solve_spd(M: Float[Array, "n n"], v: Float[Array, " n"]) -> Float[Array, " n"]:
    """M⁻¹ v for a small symmetric positive definite M (n ≤ 4), unrolled elimination.

    Gaussian elimination without pivoting is stable for SPD matrices; the loops are Python
    loops over the static size, so the solve is a handful of fused scalar operations.
    """
    n = M.shape[-1]
    A = [[M[i, j] for j in range(n)] for i in range(n)]
    b = [v[i] for i in range(n)]
    for k in range(n):
        for i in range(k + 1, n):
            f = A[i][k] / A[k][k]
            for j in range(k + 1, n):
                A[i][j] = A[i][j] - f * A[k][j]
            b[i] = b[i] - f * b[k]
    x = [None] * n
    for i in reversed(range(n)):
        s = b[i]
        for j in range(i + 1, n):
            s = s - A[i][j] * x[j]
        x[i] = s / A[i][i]
    return jnp.stack(x)


def _order_key(x: Float[Array, " n"]) -> Array:
    """uint32 keys whose unsigned order is the float32 order of ``x`` (NaN excluded)."""
    bits = lax.bitcast_convert_type(x, jnp.uint32)
    negative = (bits >> 31) == 1
    return jnp.where(negative, ~bits, bits | jnp.uint32(0x80000000))


def _from_key(key: Array) -> Float[Array, " k"]:
    negative = (key >> 31) == 0
    bits = jnp.where(negative, ~key, key & jnp.uint32(0x7FFFFFFF))
    return lax.bitcast_convert_type(bits, jnp.float32)


def masked_median(x: Float[Array, " n"], mask: Bool[Array, " n"]) -> Float[Array, ""]:
    """``jnp.nanmedian(jnp.where(mask, x, nan))`` without a sort (float32; others sort).

    The lower middle order statistic is found by bisection on the 32-bit keys of the values
    (counting passes over the points, exact), the upper one from it in one more pass (the
    same value, or the least key above it), and the two are averaged; NaN when no point is
    selected. No gradient flows through it (it is a weighting constant of the IRLS loops).

    The bisection starts from the selected keys' range [min, max] and stops as soon as its
    bracket [lo, hi] holds a single point (it keeps the counts #(key < lo) and #(key ≤ hi)),
    so it takes ≈ log₂ of the number of points rather than 32 passes: 11.2 on average over
    the 20 400 medians of 24 tracking frames (sunny video, seed 0; at most 20, and at most 32
    when the median is a value repeated many times); the bracket and the counts are one
    uint32 vector, so a pass is one fused update; after it, the two middle keys come from
    the bracket in one pass (no count of the lower one). A chain of 13 medians of 640 points
    (the plate fit's IRLS) went 11.4 → 6.4 µs a median (300 interleaved calls, load 6–7), the
    weld features of 24 tracking frames 2.31 → 2.16 ms (800 interleaved calls, load 7; the
    medians' share, by a stub, 0.52 → 0.37 ms; issue 13); a whole frame, below the
    scatter at load 5–7 (experiments.ab_tracking, 300 interleaved frames): `Tracker.step`
    8.23 → 8.13 ms, tracking mode with MED 11.48 → 11.48 ms, outputs identical.
    Before, bisecting for the lower rank alone (rather than both ranks in each pass) took a
    median of 640 points from 14.8 to 9.7 µs (issue 13; interleaved, same run, load 23).
    Tried against the 32-pass bisection (13 chained medians of 640 points in one loop, 300
    interleaved calls, load 8–9): a sort of the uint32 keys 1.5× and of the floats 6×
    slower, digit searches resolving 2 or 4 bits a pass (3 or 15 counts at once) 1.5–2.3×
    slower; and against the bracketed bisection (load 6): its bracket split into 4 or 8 in
    a pass (3 or 7 counts, 7.7 or 5.3 passes on random data) 1.6–1.7× slower.
    Tried again for the kernel count (issue 13; XLA's CPU backend runs a pass as 7 kernels:
    the midpoint, the comparison, the count split in two reductions, the bracket update,
    a copy and the loop test): counting over the keys as (20, 32) blocks, and 3 thresholds a
    pass on those blocks (13 chained medians of 640 points: 1355 → 1043 and → 732 kernels)
    took the chain 129 → 121 µs and 121 → 128 µs (400 interleaved calls), the weld features
    1.126 → 1.135 ms and 2.09 → 2.45 ms (600 interleaved calls, load 8–9); a sort of the
    keys 1.089 → 1.204 ms. What a median costs is its passes over the points, not the
    kernels' dispatch.
    Not kept either (speed13d): the IRLS loops' medians warm-started, the first bracket
    taken around the previous iteration's median (± 4× its last change, within 1/64 and
    1/2 of it; one more counting pass to place the rank, exact whatever the guess): 11.2
    → 7.2 passes a median on average (384 medians of 8 tracking frames, sunny video seed
    0), outputs identical, but the plate fit alone 98.8 → 102.4 µs p10 (paired +7.5 µs,
    2000 interleaved calls, load 8) and the weld features 0.870 → 0.872 ms median
    (`experiments.ab_weld`, 400 calls, load 8): the passes are not what a median costs.
    """
    x = lax.stop_gradient(x)
    if x.dtype != jnp.float32:  # the keys are 32-bit: other dtypes take the sort
        return jnp.nanmedian(jnp.where(mask, x, jnp.nan))
    keep = mask & ~jnp.isnan(x)
    k = jnp.sum(keep.astype(jnp.int32))
    top = jnp.uint32(0xFFFFFFFF)
    key = jnp.where(keep, _order_key(x), top)
    rank = jnp.maximum((k - 1) // 2, 0).astype(jnp.uint32)
    zero = jnp.uint32(0)

    # b = (lo, hi, #(key < lo), #(key <= hi)): the rank-th key lies in [lo, hi]
    def more(b):
        return (b[0] < b[1]) & (b[3] - b[2] > 1)

    def step(b):
        mid = b[0] + (b[1] - b[0]) // 2
        n = jnp.sum(key <= mid, dtype=jnp.uint32)
        return jnp.where(
            n > rank, jnp.stack([b[0], mid, b[2], n]), jnp.stack([mid + 1, b[1], n, b[3]])
        )

    b0 = jnp.stack([jnp.min(key), jnp.max(jnp.where(keep, key, zero)), zero, k.astype(jnp.uint32)])
    b = lax.while_loop(more, step, b0)
    # The one key in [lo, hi] (or lo = hi, a repeated value) is the rank-th: the largest
    # key ≤ hi. No key lies in (low, hi], so #(key ≤ low) = #(key ≤ hi) and the least key
    # above low is the least above hi; rank k // 2 is low itself if it is repeated there.
    low = jnp.max(jnp.where(key <= b[1], key, zero))
    repeated = b[3] > (k // 2).astype(jnp.uint32)
    high = jnp.where(repeated, low, jnp.min(jnp.where(key > b[1], key, top)))
    mid2 = _from_key(jnp.stack([low, high]))
    return jnp.where(k > 0, 0.5 * (mid2[0] + mid2[1]), jnp.nan)


def window_nanmedian(z: Float[Array, " n"], k: int) -> Float[Array, " n"]:
    """``jnp.nanmedian`` of every window z[i − k .. i + k] (NaN past the ends), unsorted.

    The 2k + 1 shifted copies of ``z`` (NaN → +inf) go through an odd–even transposition
    network (2k + 1 passes of elementwise min/max, one fused kernel) and the two middle
    values of the non-NaN ones are averaged as `jnp.nanmedian` does (0.5·lo + 0.5·hi, NaN
    when the window holds no number): the same values bit for bit
    (tests/runtime/test_small_ops.py). The profile clean-up of the pipeline takes it with
    k = 4 on both stripes every frame; as a sort over (n, 9) windows it cost 0.68 of the
    clean-up's 0.77 ms (issue 13).
    """
    n = z.shape[0]
    m = 2 * k + 1
    zp = jnp.pad(z, (k, k), constant_values=jnp.nan)
    cols = [lax.slice_in_dim(zp, j, j + n) for j in range(m)]
    count = sum((~jnp.isnan(c)).astype(jnp.int32) for c in cols)
    v = [jnp.where(jnp.isnan(c), jnp.inf, c) for c in cols]
    for p in range(m):
        for i in range(p % 2, m - 1, 2):
            v[i], v[i + 1] = jnp.minimum(v[i], v[i + 1]), jnp.maximum(v[i], v[i + 1])
    lo_i, hi_i = (count - 1) // 2, count // 2
    lo = sum(jnp.where(lo_i == i, v[i], 0.0) for i in range(m))
    hi = sum(jnp.where(hi_i == i, v[i], 0.0) for i in range(m))
    return jnp.where(count > 0, 0.5 * lo + 0.5 * hi, jnp.nan).astype(z.dtype)


def one_function(f: Callable[..., Any], x: Array, *args) -> Any:
    """``f(x, *args)``, run inside a while loop of one trip so that XLA's CPU backend compiles
    it as one function (with `cslx.environment.small_loops`, the default of ``configure``).

    The CPU backend launches each fused operation of a program as its own task (≈ 0.7 µs of
    dispatch each in a `jax.profiler` trace), but compiles a while loop without a library
    call into a single function (XLA's small while-loop hoisting: no custom call; in jaxlib
    0.10 no scatter, sort or matrix product either, else the loop stays a loop of tasks).
    The loop's condition is one it cannot fold (an entry of the float array ``x`` is finite
    or is not), so the loop is kept; the values are those of ``f(x, *args)`` bit for bit
    (tests/runtime/test_small_ops.py). A while loop has no reverse-mode derivative: callers
    that differentiate call ``f`` itself. Used on the clipped-core fill
    (`cslx.runtime.band_input._fill`) and the followed bead's fit
    (`cslx.runtime.weld.stripe_feature`, ≈ 180 fused operations; issue 13): the horizontal
    stripe's feature 0.397 → 0.361 ms median, p10 0.343 → 0.314 (1000 interleaved calls on
    12 tracking frames of the sunny video, seed 0, load 4.5). Not kept: the profile
    clean-ups and the clip weights of `cslx.runtime.pipeline._process` each as one function
    (jitted alone 0.095 → 0.061 and 0.206 → 0.132 ms, but `Tracker.step` 3.18 → 3.17 ms, 400
    interleaved frames, load 2.5–2.9, and the outputs moved by 1.7e-4: the loop boundary
    keeps XLA from fusing the triangulation into the clean-up, and the rounding changes).
    """
    shapes = jax.eval_shape(f, x, *args)
    init = jax.tree_util.tree_map(lambda a: jnp.zeros(a.shape, a.dtype), shapes)
    probe = jnp.ravel(x)[0]
    go = jnp.isfinite(probe) | ~jnp.isfinite(probe)  # True, unknown to XLA

    def body(carry):
        return jnp.zeros((), bool), f(x, *args)

    return lax.while_loop(lambda carry: carry[0], body, (go, init))[1]
