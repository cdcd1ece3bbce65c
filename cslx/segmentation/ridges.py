"""The stripe as a whole: candidate ridges per column linked by dynamic programming.

`steger_centres` keeps, in every column, the strongest ridge point. Anything stronger than
the laser in one column — a sunlit edge, a glint, the other stripe at the crossing, the edge
of a printed square — then wins that column and becomes a gross error; a weak stretch of the
laser is lost. The laser line differs from all of these by being *one continuous curve across
the image*. This module finds that curve:

1. Ridge points, two ways (`linked_centres(sigma_along=...)`):
   - Hessian (`sigma_along=None`): Steger's analysis at scale σ (`cslx.segmentation.steger`,
     Steger 1998 eqs. (10)–(17)): strength −λ (λ the most negative Hessian eigenvalue),
     normal n and the Taylor step t to the line centre. Bright ridges only (λ < 0), normals
     within `max_angle_deg` of the search axis (the other stripe of a cross runs across it).
   - Column profiles (`sigma_along` in px, the default of `cslx.segmentation.robust`): the
     image smoothed by `sigma_along` along the stripe and differentiated by σ across it; per
     column the maxima of the profile, t = −r_v / r_vv (eq. (17) in 1-D), strength −r_vv.
     Along a column a straight stripe of any tilt has a symmetric profile, so no normal is
     needed, and the other stripe of the cross — constant along the column — adds nothing
     to r_v and r_vv: at the crossing, where the Hessian's eigenvectors mix the two stripes
     (misses and 1–4 px errors on the development frames), the column profiles measure
     through. The longer smoothing along the stripe also averages the laser speckle, which
     dominates the error of rendered frames (without speckle the median error drops from
     0.08 to 0.01 px on clean scenes).
2. Candidates. Per column (horizontal stripe; per row for the vertical one) the K strongest
   local maxima of the strength along the column, with sub-pixel position (Hessian:
   v + t/n_v, Steger's step to the crossing of the local line with the column), strength in
   units of the frame's ridge noise z (Hessian: −λ / mean|λ|; column profiles: −r_vv over
   1.18 × median|r_vv|, the median because a broad or clipped stripe can dominate the mean
   once the noise is smoothed away), and the width of the smoothed profile
   w² = −r/r_nn − σ² (Steger 1998 §4: r''/r = −1/(s² + σ²) at the centre of a Gaussian
   profile of standard deviation s; background removed with the column's median).
3. Linking. A Viterbi pass (`jax.lax.scan` over the columns) chooses for every column one
   candidate or "no stripe", minimising

       Σ_j [ −min(log(z/z0), c_max) ]                 (reward: presence, capped)
     + Σ β · max(|Δv| − a·n, 0)²  (≤ J)                (smoothness; a jump costs at most J)
     + Σ γ · (log w − log w_prev)²                      (the width stays the laser's)
     + g per missing column inside the path            (gaps are allowed, but cost)

   with one path that starts and ends anywhere (states: K candidates, gap, before, after).
   The reward is capped, so a distractor brighter than the laser does not pay for the jumps
   onto and off it: the longest consistent curve wins.
4. Refinement and confidence. The chosen candidates keep their sub-pixel position. A
   centre farther than `LinkParams.reject_px` from the line through its neighbours (±6
   columns, itself excluded; sums in the window's own coordinates, float32-safe) is dropped:
   the other stripe's core at a crossing and split clipped cores. A short piece of the path
   (< `DETOUR_LENGTH` centres between gaps) lying more than `DETOUR_PX` off the line between
   the path on its two sides is dropped too: a bright speck the path visited inside a
   stretch where the laser is absorbed (black print) or hidden. Each centre gets a predicted
   standard deviation along the search axis, σ_pos = max(σ_noise ‖∂g‖₂ ‖g‖₂ / |r_nn|,
   s_path): the first term propagates white pixel noise through the Taylor step
   t = −r_n / r_nn (per centre); the second is the path's own robust scatter about its local
   line (MAD of second differences at lag 12, per frame), which also carries the laser
   speckle and texture that white noise misses.

Pure JAX, jit-compiled, vmap-able over frames (σ, `sigma_along`, K and the axis are static).
No sorts of whole frames: medians are bisections on counts (`_median`), since XLA's CPU sort
of a 640×480 frame alone cost ≈ 100 ms.
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .steger import Centres, _check_image, _filter_axis, _ridge, _taps

__all__ = [
    "LinkParams",
    "Candidates",
    "candidates",
    "drop_stray",
    "link",
    "linked_centres",
    "noise_std",
]


class LinkParams(NamedTuple):
    """Weights of the path cost (see the module docstring); all dimensionless or in pixels.

    Attributes:
        z0: ridge strength (in units of the frame's mean |λ|) at which a candidate's reward
            is zero; weaker ones cost, stronger ones pay (log z/z0).
        z_min: candidates below this strength are not considered at all.
        reward_cap: largest reward of one candidate (log units).
        slope: free displacement per column (px) before the smoothness cost starts.
        beta: smoothness weight per px² beyond `slope`.
        jump: largest smoothness cost of one step (a jump to another curve).
        gamma: weight of the change of log width between linked candidates.
        gap: cost of one column without a centre inside the path.
        min_length: a path with fewer centres is no stripe.
        reject_px: a linked centre farther than this (px, along the search axis) from the
            line through its neighbours (±6 columns) is dropped as an outlier.
    """

    z0: float = 5.0
    z_min: float = 2.0
    reward_cap: float = 1.0
    slope: float = 1.0
    beta: float = 0.5
    jump: float = 6.0
    gamma: float = 0.5
    gap: float = 0.6
    min_length: int = 12
    reject_px: float = 1.0


class Candidates(NamedTuple):
    """K candidate ridge points per column (axis 0) or row (axis 1): (N, K) arrays."""

    pos: jax.Array  # sub-pixel coordinate along the search axis
    z: jax.Array  # strength −λ / mean|λ| (0 where there is no candidate)
    width: jax.Array  # standard deviation of the unsmoothed profile (px), ≥ 0.3
    slope_n: jax.Array  # |n_along|, the cosine between the normal and the search axis
    sigma_px: jax.Array  # predicted std of pos (px)


def noise_std(image: jax.Array) -> jax.Array:
    """Robust std of the pixel noise: MAD of the 4-neighbour Laplacian / √20 (Gaussian noise)."""
    lap = (
        4 * image[1:-1, 1:-1]
        - image[:-2, 1:-1]
        - image[2:, 1:-1]
        - image[1:-1, :-2]
        - image[1:-1, 2:]
    )[::2, ::2].reshape(-1)  # a quarter of the pixels: the scale, at a quarter of the cost
    mad = _median(jnp.abs(lap - _median(lap)))
    return lax.stop_gradient(1.4826 * mad / math.sqrt(20.0))


def _median(x, axis: int = 0, iters: int = 24):
    """Median along `axis` by bisection on counts, no sort (XLA's CPU sort of a 640×480
    frame costs ≈ 100 ms; 24 counting passes a few ms). Returns the lower middle value to
    within (max − min) / 2²⁴; no gradient (it sets scales and backgrounds)."""
    x = lax.stop_gradient(x)
    lo, hi = jnp.min(x, axis=axis), jnp.max(x, axis=axis)
    half = 0.5 * x.shape[axis]

    def body(_, bounds):
        lo, hi = bounds
        mid = 0.5 * (lo + hi)
        below = jnp.sum(x <= jnp.expand_dims(mid, axis), axis=axis)
        up = below < half
        return jnp.where(up, mid, lo), jnp.where(up, hi, mid)

    lo, hi = lax.fori_loop(0, iters, body, (lo, hi))
    return hi


def _candidates(image, sigma: float, k: int, max_angle_deg: float) -> Candidates:
    """Candidates of a horizontal stripe (one set per column); `image` is (H, W)."""
    ridge = _ridge(image, sigma, 0.6)
    min_cos = math.cos(math.radians(max_angle_deg))
    steep = jnp.abs(ridge.nv) >= min_cos
    score = jnp.where(ridge.geometric & steep & (ridge.strength > 0), ridge.strength, 0.0)
    # Non-maximum suppression along the column (ties go to the upper pixel).
    up = jnp.pad(score[:-1], ((1, 0), (0, 0)))
    down = jnp.pad(score[1:], ((0, 1), (0, 0)))
    score = jnp.where((score > up) & (score >= down), score, 0.0)
    top, idx = lax.top_k(score.T, k)  # (W, K)
    col = jnp.arange(score.shape[1])[:, None]
    safe_nv = jnp.where(steep, ridge.nv, 1.0)
    offset = (ridge.t / safe_nv)[idx, col]
    pos = idx.astype(image.dtype) + jnp.clip(offset, -1.0, 1.0)
    z = top / jnp.maximum(ridge.scale, jnp.finfo(image.dtype).tiny)
    # Width from the smoothed value and curvature at the candidate: s² + σ² = −r / r_nn.
    smooth = _filter_axis(_filter_axis(image, sigma, (0,), 0)[0], sigma, (0,), 1)[0]
    background = _median(smooth, axis=0)
    r = smooth[idx, col] - background[:, None]
    lam = jnp.maximum(top, jnp.finfo(image.dtype).tiny)
    s2 = jnp.clip(r / lam - sigma**2, 0.09, 2500.0)
    width = jnp.where(top > 0, jnp.sqrt(s2), 0.3)
    # Position noise: std of r_n under white noise over std of t = −r_n / r_nn, along the axis.
    g0, g1 = _taps(sigma, 0), _taps(sigma, 1)
    norm0 = math.sqrt(g0[0] ** 2 + 2 * np.sum(g0[1:] ** 2))
    norm1 = math.sqrt(2 * np.sum(g1[1:] ** 2))
    nabs = jnp.abs(ridge.nv)[idx, col]
    sig = noise_std(image) * norm0 * norm1 / lam / jnp.maximum(nabs, min_cos)
    return Candidates(pos, jnp.where(top > 0, z, 0.0), width, nabs, sig)


def _candidates_column(image, sigma: float, k: int, sigma_along: float, along=None) -> Candidates:
    """Candidates of a horizontal stripe from the column profiles of a smoothed image.

    The image is smoothed along the stripe (axis 1, `sigma_along`) and differentiated across
    it (axis 0, `sigma`); each column's profile maxima are located by the Taylor step
    t = −r_v / r_vv along the column (Steger 1998 eq. (17) in 1-D), strength −r_vv. Along a
    column a straight stripe of any tilt has a symmetric profile, so no normal is needed, and
    the other stripe of the cross — constant along the column — adds nothing to r_v, r_vv.
    """
    # Work on the transpose (columns as rows): the filters across the stripe, the
    # non-maximum suppression and top K then run along the contiguous axis, which XLA's CPU
    # fusions handle ≈ 3× faster than the same along axis 0 (35 → 10 ms per frame).
    x = image.T
    if along is None:
        (a,) = _filter_axis(x, sigma_along, (0,), 0)
    else:  # x smoothed along a turned stripe (`orient.smooth_along`), computed once
        a = along
    smooth, rv, rvv = _filter_axis(a, sigma, (0, 1, 2), 1)  # (W, H)
    tiny = jnp.finfo(image.dtype).tiny
    neg = rvv < 0
    score = jnp.where(neg & (jnp.abs(rv) <= -0.6 * rvv), -rvv, 0.0)  # |t| ≤ 0.6
    up = jnp.pad(score[:, :-1], ((0, 0), (1, 0)))
    down = jnp.pad(score[:, 1:], ((0, 0), (0, 1)))
    score = jnp.where((score > up) & (score >= down), score, 0.0)
    top, idx = lax.top_k(score, k)  # (W, K)
    col = jnp.arange(score.shape[0])[:, None]
    t = -rv[col, idx] / jnp.minimum(rvv[col, idx], -tiny)
    pos = idx.astype(image.dtype) + jnp.clip(jnp.where(top > 0, t, 0.0), -1.0, 1.0)
    # Noise level of −r_vv: the median |r_vv| (× 1.18, the mean-to-median ratio of |Gaussian|,
    # so that z matches the Hessian candidates' mean |λ| on noise) — the median, not the
    # mean, because after smoothing along the stripe a broad or clipped stripe can dominate
    # the frame's mean.
    scale = 1.1829 * _median(jnp.abs(rvv[::2, ::2]).reshape(-1))
    z = top / jnp.maximum(scale, tiny)
    background = _median(smooth, axis=1)
    r = smooth[col, idx] - background[:, None]
    lam = jnp.maximum(top, tiny)
    s2 = jnp.clip(r / lam - sigma**2, 0.09, 2500.0)
    width = jnp.where(top > 0, jnp.sqrt(s2), 0.3)
    g0, g1 = _taps(sigma_along, 0), _taps(sigma, 1)
    norm0 = math.sqrt(g0[0] ** 2 + 2 * np.sum(g0[1:] ** 2))
    norm1 = math.sqrt(2 * np.sum(g1[1:] ** 2))
    sig = noise_std(image) * norm0 * norm1 / lam
    return Candidates(pos, jnp.where(top > 0, z, 0.0), width, jnp.ones_like(pos), sig)


def _link(c: Candidates, p: LinkParams) -> jax.Array:
    """Viterbi over columns: (N,) index of the chosen candidate, −1 where none."""
    n, k = c.pos.shape
    dtype = c.pos.dtype
    inf = jnp.asarray(jnp.inf, dtype)
    ok = c.z >= p.z_min
    cost_on = jnp.where(ok, -jnp.minimum(jnp.log(jnp.maximum(c.z, 1e-6) / p.z0), p.reward_cap), inf)
    logw = jnp.where(ok, jnp.log(jnp.clip(c.width, 0.3, 50.0)), 0.0)
    gap_i, pre_i, post_i = k, k + 1, k + 2

    def trans(d, steps, dlogw):
        smooth = p.beta * jnp.maximum(jnp.abs(d) - p.slope * steps, 0.0) ** 2
        return jnp.minimum(smooth, p.jump) + p.gamma * dlogw**2

    def step(carry, xs):
        cost, mem_pos, mem_w, mem_len = carry
        pos, con, lw = xs
        # into candidate k from candidate k' (K×K), from the gap, from "before"
        from_on = cost[:k, None] + trans(
            pos[None, :] - mem_pos[:k, None], 1.0, lw[None, :] - mem_w[:k, None]
        )
        from_gap = cost[gap_i] + trans(
            pos - mem_pos[gap_i], mem_len[gap_i] + 1.0, lw - mem_w[gap_i]
        )
        from_pre = jnp.broadcast_to(cost[pre_i], (k,))
        options = jnp.concatenate([from_on, from_gap[None], from_pre[None]], 0)  # (K+2, K)
        src_on = jnp.argmin(options, axis=0)
        new_on = jnp.min(options, axis=0) + con
        src_on = jnp.where(src_on == k, gap_i, jnp.where(src_on == k + 1, pre_i, src_on))
        # into the gap from a candidate or the gap
        gap_opts = cost[: k + 1] + p.gap
        src_gap = jnp.argmin(gap_opts)
        new_gap = gap_opts[src_gap]
        # "after": from any candidate, the gap or itself, free
        post_opts = jnp.concatenate([cost[: k + 1], cost[post_i : post_i + 1]])
        src_post = jnp.argmin(post_opts)
        src_post = jnp.where(src_post == k + 1, post_i, src_post)
        new_cost = jnp.concatenate(
            [new_on, new_gap[None], cost[pre_i : pre_i + 1], jnp.min(post_opts)[None]]
        )
        new_pos = jnp.concatenate([pos, mem_pos[src_gap][None], mem_pos[pre_i:]])
        new_w = jnp.concatenate([lw, mem_w[src_gap][None], mem_w[pre_i:]])
        new_len = jnp.concatenate(
            [jnp.zeros(k, dtype), (mem_len[src_gap] + 1.0)[None], mem_len[pre_i:]]
        )
        back = jnp.concatenate([src_on, src_gap[None], jnp.asarray([pre_i]), src_post[None]])
        return (new_cost, new_pos, new_w, new_len), back.astype(jnp.int32)

    zeros = jnp.zeros(3, dtype)
    init = (
        jnp.concatenate([cost_on[0], jnp.asarray([inf, 0.0, inf], dtype)]),
        jnp.concatenate([c.pos[0], zeros]),
        jnp.concatenate([logw[0], zeros]),
        jnp.zeros(k + 3, dtype),
    )
    (cost, _, _, _), back = lax.scan(step, init, (c.pos[1:], cost_on[1:], logw[1:]))
    last = jnp.argmin(cost).astype(jnp.int32)

    def trace(state, b):
        prev = b[state]
        return prev, state

    first, states = lax.scan(trace, last, back, reverse=True)
    states = jnp.concatenate([first[None], states])
    return jnp.where(states < k, states, -1)


@functools.partial(jax.jit, static_argnames=("sigma", "axis", "k", "max_angle_deg", "sigma_along"))
def _linked(
    image, params, *, sigma, axis, k, max_angle_deg, sigma_along=None, slope=None, along=None
):
    img = image if axis == 0 else image.T
    if sigma_along is None:
        c = _candidates(img, sigma, k, max_angle_deg)
    else:
        c = _candidates_column(img, sigma, k, sigma_along, along)
    # a turned stripe (`orient`) is linked by its offsets from the line of its slope
    line = 0.0 if slope is None else slope * jnp.arange(c.pos.shape[0], dtype=c.pos.dtype)
    choice = _link(c if slope is None else c._replace(pos=c.pos - line[:, None]), params)
    valid = choice >= 0
    pick = jnp.maximum(choice, 0)[:, None]

    def take(a):
        return jnp.take_along_axis(a, pick, 1)[:, 0]

    count = jnp.sum(valid)
    z = jnp.where(valid, take(c.z), 0.0)
    median_z = _masked_median(z, valid)
    stripe = (count >= params.min_length) & (median_z >= params.z0)
    valid = valid & stripe
    pos = take(c.pos)
    # Outliers along the path (the other stripe's core at a crossing, a split clipped core):
    # a centre farther than `reject_px` from the line fitted to its neighbours is dropped.
    resid = _local_residual(pos, valid, PATH_HALF_WINDOW)
    valid = valid & ~(jnp.abs(resid) > params.reject_px)
    valid = _drop_detours(pos, valid)
    pos = jnp.where(valid, pos, jnp.nan)
    width = jnp.where(valid, take(c.width), jnp.nan)
    # Predicted std: the Hessian term of the white pixel noise, or the scatter of the path
    # about its local line where larger (speckle and texture move the centre more than sensor
    # noise; the scatter already contains the white-noise part).
    scatter = _path_scatter(pos, valid, 2 * PATH_HALF_WINDOW)
    sig = jnp.where(valid, jnp.maximum(take(c.sigma_px), scatter), jnp.nan)
    return Centres(pos, valid, jnp.where(valid, z, 0.0), sig), width


#: A piece of the path shorter than this (centres) is a detour when it lies more than
#: `DETOUR_PX` off the straight line between the path on its two sides.
DETOUR_LENGTH = 16
DETOUR_PX = 3.0


def _drop_detours(pos, valid):
    """Drop short pieces of the path that leave the line and come back (a bright speck of the
    other stripe or a glint inside a stretch where the laser is absorbed or hidden): a piece
    (valid centres, no gap) of fewer than `DETOUR_LENGTH` centres whose mean lies more than
    `DETOUR_PX` from the straight line between the valid centres just before and after it."""
    n = pos.shape[0]
    j = jnp.arange(n)
    start = valid & ~jnp.concatenate([jnp.zeros(1, bool), valid[:-1]])
    seg = jnp.cumsum(start) - 1  # piece index of every valid centre
    seg = jnp.where(valid, seg, n)
    ones = valid.astype(pos.dtype)
    length = jax.ops.segment_sum(ones, seg, n + 1)
    total = jax.ops.segment_sum(jnp.where(valid, pos, 0.0), seg, n + 1)
    first = jax.ops.segment_min(jnp.where(valid, j, n), seg, n + 1)
    last = jax.ops.segment_max(jnp.where(valid, j, -1), seg, n + 1)
    before = jnp.clip(first - 1, 0, n - 1)
    after = jnp.clip(last + 1, 0, n - 1)
    # Nearest valid centres outside the piece on each side.
    prev_valid = lax.cummax(jnp.where(valid, j, -1))
    next_valid = lax.cummin(jnp.where(valid, j, n), reverse=True)
    p = prev_valid[before]
    q = next_valid[after]
    both = (first > 0) & (last < n - 1) & (p >= 0) & (p < first) & (q < n) & (q > last)
    pp, qq = jnp.clip(p, 0, n - 1), jnp.clip(q, 0, n - 1)
    mid = 0.5 * (first + last)
    line = pos[pp] + (mid - pp) * (pos[qq] - pos[pp]) / jnp.maximum(qq - pp, 1)
    mean = total / jnp.maximum(length, 1.0)
    detour = both & (length < DETOUR_LENGTH) & (jnp.abs(mean - line) > DETOUR_PX)
    return valid & ~detour[jnp.minimum(seg, n)]


#: A piece of the path after a gap, shorter than `STRAY_LENGTH` centres, is stray when its
#: mean lies more than `STRAY_PX` + `STRAY_SLOPE` × the gap off the path (`drop_stray`).
STRAY_LENGTH = 32
STRAY_PX = 20.0
STRAY_SLOPE = 1.0


def drop_stray(pos, valid):
    """Drop short pieces of the path far off it across a gap: the detour test of
    `_drop_detours` for longer pieces with a wider margin (`STRAY_LENGTH`, `STRAY_PX`,
    `STRAY_SLOPE`), and for the path's two ends, where there is no path on the far side: an
    end piece is compared with the path's last centre before the gap. The references are
    the nearest centres of pieces of at least `STRAY_LENGTH` (a stray piece must not judge
    its neighbours).

    On rendered frames such pieces were bright stretches beside the crossing of a 16 px
    wide stripe, 150–190 px off the stripe, that the path smoothing then joined to it with
    lines. A 4 mm sheet (12–25 px above half maximum) at 640×480, the four presets, dev
    seeds 8800–8805 (one frame each), linked detector (`cslx.segmentation.robust`, which
    applies this before and after its bridging), vertical stripe: gross (> 1 mm) 3.09 →
    0.00 %, detection 90.97 → 88.33 % (the dropped centres were the wrong ones; sunny 72.9
    → 65.0 %, the rest of the stripe there lies under clipped sunlight), median 0.161 →
    0.149 mm, p95 0.688 → 0.478 mm; horizontal unchanged (gross 0.26 %, detection 91.8 %).
    Development frames (seeds 7100–7117, 2 frames × 18 conditions) and the flat wall
    (seeds 41–46): every figure unchanged.
    """
    n = pos.shape[0]
    j = jnp.arange(n)
    start = valid & ~jnp.concatenate([jnp.zeros(1, bool), valid[:-1]])
    seg = jnp.where(valid, jnp.cumsum(start) - 1, n)
    length = jax.ops.segment_sum(valid.astype(pos.dtype), seg, n + 1)
    mean = jax.ops.segment_sum(jnp.where(valid, pos, 0.0), seg, n + 1) / jnp.maximum(length, 1)
    first = jax.ops.segment_min(jnp.where(valid, j, n), seg, n + 1)
    last = jax.ops.segment_max(jnp.where(valid, j, -1), seg, n + 1)
    # the references: the nearest centres of long pieces on either side
    anchor = valid & (length[jnp.minimum(seg, n)] >= STRAY_LENGTH)
    prev_valid = lax.cummax(jnp.where(anchor, j, -1))
    next_valid = lax.cummin(jnp.where(anchor, j, n), reverse=True)
    p = jnp.where(first > 0, prev_valid[jnp.clip(first - 1, 0, n - 1)], -1)
    q = jnp.where(last < n - 1, next_valid[jnp.clip(last + 1, 0, n - 1)], n)
    pp, qq = jnp.clip(p, 0, n - 1), jnp.clip(q, 0, n - 1)
    mid = 0.5 * (first + last)
    line = pos[pp] + (mid - pp) * (pos[qq] - pos[pp]) / jnp.maximum(qq - pp, 1)
    before, after = p >= 0, q < n
    ref = jnp.where(before & after, line, jnp.where(before, pos[pp], pos[qq]))
    gap = jnp.minimum(jnp.where(before, first - p, n), jnp.where(after, q - last, n))
    far = jnp.abs(mean - ref) > STRAY_PX + STRAY_SLOPE * gap.astype(pos.dtype)
    stray = (before | after) & (length < STRAY_LENGTH) & far
    return valid & ~stray[jnp.minimum(seg, n)]


#: Half window (columns) of the local line that judges a centre against its neighbours.
PATH_HALF_WINDOW = 6


def _window_moment(x, h: int, power: int):
    """Σ_{m=−h..h, m≠0} x[j+m] m^power (zero padded): sums in the window's own coordinates,
    so float32 keeps them exact far from column 0 (global sums of x² cancel)."""
    m = np.arange(-h, h + 1, dtype=float)
    kernel = np.where(m == 0, 0.0, m**power)[::-1]  # convolution flips the kernel
    return jnp.convolve(x, jnp.asarray(kernel, x.dtype), mode="same")


def _local_residual(pos, valid, h):
    """pos − (least-squares line through the valid neighbours j−h..j+h, j itself excluded)."""
    w = valid.astype(pos.dtype)
    y = jnp.where(valid, pos, 0.0)
    sw = _window_moment(w, h, 0)
    sx = _window_moment(w, h, 1)
    sxx = _window_moment(w, h, 2)
    sy = _window_moment(y, h, 0)
    sxy = _window_moment(y, h, 1)
    det = sw * sxx - sx * sx
    ok = (sw >= 4) & (det > 1e-6)
    safe = jnp.where(ok, det, 1.0)
    b = (sw * sxy - sx * sy) / safe
    a = (sy - b * sx) / jnp.where(ok, sw, 1.0)  # the line's value at j itself (x = 0)
    return jnp.where(ok & valid, pos - a, 0.0)


#: Order of the difference behind `_path_scatter`: 2 (default) or 3. See there.
SCATTER_ORDER = 2


def _path_scatter(pos, valid, lag, order=None):
    """Robust std of the path's centres about the smooth path, from the MAD of a difference
    at lag L: order 2, d_j = pos_j − (pos_{j−L} + pos_{j+L})/2, Var(d) = 1.5 s² for
    independent errors of std s; order 3, d_j = pos_j − 3 pos_{j+L} + 3 pos_{j+2L} −
    pos_{j+3L}, Var(d) = (1 + 9 + 9 + 1) s² = 20 s². MAD → std by 1.4826. None:
    `SCATTER_ORDER` (read when traced).

    The second difference also measures the path's own shape: a curvature κ adds κL²/2 to
    every term, so a path curved along its whole length reads as noisy, and the ICI
    smoothing (`cslx.segmentation.path`), which takes this scatter as its noise, then
    chooses windows too long for the curve. A sine of amplitude 40 px and period 500 px
    (tests/segmentation/test_refine.py): median error after `refine.second_pass` 0.116 px
    with order 2, 0.03 px with order 3 (straight: 0.004 px either way). The third
    difference is zero on any quadratic.

    Why order 2 stays the default (issue 11; development seeds 7100–7117, 18 conditions,
    H / V median / p95 mm, all three uses — the centres' `sigma`, the first pass's and
    the second pass's path smoothing): frames 0–1 (36 frames, `experiments.robust_extraction`)
    0.0300 / 0.1347, 0.0313 / 0.1438 → 0.0300 / 0.1343, 0.0320 / 0.1453 (detection and gross
    unchanged; clean H p95 0.096 → 0.091, green H 0.116 → 0.123, saturated V 0.127 → 0.133).
    Order 3 only in the second pass's final smoothing, frames 0–1: 0.0301 / 0.1346, 0.0322 /
    0.1438; fresh frame 2 (18 frames): 0.0290 / 0.1397, 0.0358 / 0.1517 → 0.0289 / 0.1399,
    0.0373 / 0.1510. On the rendered stripes the curvature term is small (median ratio of
    the two estimates 1.07 H / 1.09 V), but the windows' choice is sensitive to it: the
    vertical stripe's median gains from the slightly larger noise (longer windows) that the
    horizontal's p95 loses. With order 3 and the second pass's correlation c 8 / 10 / 12:
    0.0302 / 0.1359, 0.0310 / 0.1432; 0.0303 / 0.1366, 0.0305 / 0.1408; 0.0309 / 0.1376,
    0.0304 / 0.1409; Γ 2.5 / 3: 0.0304 / 0.1357, 0.0307 / 0.1420; 0.0319 / 0.1389, 0.0304
    / 0.1467; lag 8 / 16 / 24 instead of 12: 0.0357 / 0.1533, 0.0424 / 0.1594; 0.0309 /
    0.1363, 0.0310 / 0.1439; 0.0328 / 0.1411, 0.0310 / 0.1528 (frame 2, lag 16: 0.0296 /
    0.1435, 0.0327 / 0.1506); with `refine.LOCAL_WEIGHTS` (final smoothing only), order 2 / 3:
    0.0297 / 0.1336, 0.0312 / 0.1393 and 0.0295 / 0.1323, 0.0316 / 0.1388 (frame 2: 0.0282 /
    0.1346, 0.0347 / 0.1495 and 0.0281 / 0.1357, 0.0377 / 0.1511). No setting improves both
    stripes. Flat wall (seeds 41–46, no
    curvature at all), order 3: worst RMS 0.066 → 0.065 px, but 19 of 24 frame-stripes
    with a larger RMS (largest distance 0.166 → 0.253 px, saturated 41 H); none beyond 0.5 px.

    Most of the two estimates' difference on rendered frames is not curvature but the
    errors' correlation along the path, to which the two differences respond differently:
    unit-std noise smoothed along the path by a Gaussian of σ 3 / 6 / 12 centres (the second
    pass averages along σ 6) reads 1.01 / 0.72 / 0.34 with order 2 and 1.01 / 0.68 / 0.24
    with order 3 (straight path, lag 12). Both underestimate a correlated error's std; the
    second pass's correlation c (`refine.REFINE_CORRELATION`) was chosen with order 2.
    """
    order = SCATTER_ORDER if order is None else order
    n = pos.shape[0]
    j = jnp.arange(n)
    if order == 2:
        lo, hi = jnp.clip(j - lag, 0, n - 1), jnp.clip(j + lag, 0, n - 1)
        ok = valid & valid[lo] & valid[hi] & (j - lag >= 0) & (j + lag < n)
        d = pos - 0.5 * (pos[lo] + pos[hi])
        var = 1.5
    elif order == 3:
        i1, i2, i3 = (jnp.clip(j + i * lag, 0, n - 1) for i in (1, 2, 3))
        ok = valid & valid[i1] & valid[i2] & valid[i3] & (j + 3 * lag < n)
        d = pos - 3.0 * pos[i1] + 3.0 * pos[i2] - pos[i3]
        var = 20.0
    else:
        raise ValueError(f"order must be 2 or 3, got {order!r}")
    mad = _masked_median(jnp.abs(jnp.where(ok, d, 0.0)), ok)
    return lax.stop_gradient(1.4826 * mad / math.sqrt(var))


def _masked_median(x, mask):
    """Median of x over mask (jit-safe: sort with +inf padding)."""
    n = jnp.sum(mask)
    s = jnp.sort(jnp.where(mask, x, jnp.inf))
    i = jnp.maximum(n - 1, 0) // 2
    j = jnp.maximum(n, 1) // 2
    return jnp.where(n > 0, 0.5 * (s[i] + s[jnp.where(n % 2 == 0, j, i)]), 0.0)


def candidates(
    image, *, sigma: float, axis: int = 0, k: int = 4, max_angle_deg: float = 60.0
) -> Candidates:
    """The K candidate ridge points of every column (axis 0) or row (axis 1)."""
    image = _check_image(image)
    img = image if axis == 0 else image.T
    return jax.jit(_candidates, static_argnums=(1, 2, 3))(img, float(sigma), k, max_angle_deg)


def link(c: Candidates, params: LinkParams = LinkParams()) -> jax.Array:
    """The linked path through candidates: (N,) chosen candidate index, −1 where none."""
    return jax.jit(_link)(c, params)


def linked_centres(
    image,
    *,
    sigma: float,
    axis: int = 0,
    k: int = 4,
    max_angle_deg: float = 60.0,
    params: LinkParams = LinkParams(),
    sigma_along: float | None = None,
    slope: float | None = None,
    along=None,
) -> tuple[Centres, jax.Array]:
    """Stripe centres of one frame by candidate linking: (`Centres` with `sigma`, width (N,)).

    Args:
        image: (H, W) monochrome image, bright stripe.
        sigma: Steger's scale in px (static).
        axis: 0 horizontal stripe (one centre per column), 1 vertical (one per row).
        k: candidates per column (static).
        max_angle_deg: largest angle of the stripe to its image axis (static; Hessian
            candidates only).
        params: `LinkParams`.
        sigma_along: None for Hessian candidates; a smoothing scale along the stripe (px,
            static) for column-profile candidates (module docstring, step 1).
        slope: None, or the stripe's slope (px across per px along, `orient.search_slope`):
            column profiles linked by their offsets from it.
        along: with `slope`, the transposed image smoothed along it (`orient.smooth_along`
            of image.T for axis 0, of image for axis 1; `sigma_along` is then unused).

    Returns:
        `Centres` (pos, valid, strength in noise units z, sigma = predicted std of pos in px)
        and the estimated profile standard deviation (px) of each centre (NaN where none).
    """
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (horizontal stripe) or 1 (vertical), got {axis!r}")
    image = _check_image(image)
    params = LinkParams(*[jnp.asarray(v, image.dtype) for v in params])
    return _linked(
        image,
        params,
        sigma=float(sigma),
        axis=axis,
        k=int(k),
        max_angle_deg=float(max_angle_deg),
        sigma_along=None if sigma_along is None else float(sigma_along),
        slope=None if slope is None else jnp.asarray(slope, image.dtype),
        along=along,
    )
