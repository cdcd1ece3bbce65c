"""Small fixed-size kernels of the bead fits that XLA's CPU backend runs slowly as library calls.

The weld features (`cslx.runtime.weld`, `cslx.runtime.junction`) solve ≈ 40 tiny normal
equations (2×2, 3×3) and take ≈ 45 medians of a 480–640-point profile per frame, inside
IRLS and Gauss–Newton loops. As `jnp.linalg.solve` (a LAPACK call each) and
`jnp.nanmedian` (a full sort) they cost ≈ 5 ms of a tracking frame; as the elementwise
kernels here they fuse into the loops (issue 13). Same values to float32 rounding
(tests/runtime/test_small_ops.py).
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax.numpy as jnp
from jax import lax

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, Bool, Float

__all__ = ["masked_median", "solve_spd", "window_nanmedian"]


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
    (32 counting passes over the points, exact), the upper one from it in one more pass (the
    same value, or the least key above it), and the two are averaged; NaN when no point is
    selected. No gradient flows through it (it is a weighting constant of the IRLS loops).
    Bisecting for the lower rank alone (rather than both ranks in each pass) took a median
    of 640 points from 14.8 to 9.7 µs (issue 13; interleaved, same run, load 23). Tried
    against it later (13 chained medians of 640 points in one loop, 300 interleaved calls,
    load 8–9): a sort of the uint32 keys 1.5× and of the floats 6× slower, digit searches
    resolving 2 or 4 bits a pass (3 or 15 counts at once) 1.5–2.3× slower.
    """
    x = lax.stop_gradient(x)
    if x.dtype != jnp.float32:  # the keys are 32-bit: other dtypes take the sort
        return jnp.nanmedian(jnp.where(mask, x, jnp.nan))
    keep = mask & ~jnp.isnan(x)
    k = jnp.sum(keep.astype(jnp.int32))
    top = jnp.uint32(0xFFFFFFFF)
    key = jnp.where(keep, _order_key(x), top)
    rank = jnp.maximum((k - 1) // 2, 0)

    def step(_, bounds):
        lo, hi = bounds
        mid = lo + (hi - lo) // 2
        ok = jnp.sum((key <= mid).astype(jnp.int32)) > rank
        return jnp.where(ok, lo, mid + 1), jnp.where(ok, mid, hi)

    _, low = lax.fori_loop(0, 32, step, (jnp.uint32(0), top))
    # rank k // 2: the same key if it is repeated there, else the least key above it
    repeated = jnp.sum((key <= low).astype(jnp.int32)) > k // 2
    high = jnp.where(repeated, low, jnp.min(jnp.where(key > low, key, top)))
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
