"""Edge-preserving smoothing of a linked stripe path: local quadratics with adaptive windows.

The linked detector (`cslx.segmentation.ridges`) measures every column (row) separately, and
the laser speckle moves each centre by ≈ 0.05–0.1 px, correlated over a few px by the
smoothing along the stripe. The true path is piecewise smooth — flat plates, a bead cap,
corners where they meet — so straight and gently curved parts may average many speckle
grains, while a corner must not be rounded (a longer Gaussian along the stripe did exactly
that: issue 11, vertical gross 0.24 → 1.3 / 3.7 % at 10 / 15 px).

`smooth_path` fits, at every centre j and for every half window h of `HALVES`, the
least-squares quadratic through the valid centres j−h … j+h (uniform weights, coordinates
m/h) and keeps the value at j, â_h, with its standard deviation

    sd_h = s · √(min(c · (M_h⁻¹)₀₀, 1)),

M_h the 3×3 normal matrix of the window (so (M_h⁻¹)₀₀ is the variance factor of the value at
the centre under white noise), s the path's robust scatter (`ridges._path_scatter`) and c =
`CORRELATION` the number of neighbouring centres that share one noise value (the smoothing
along the stripe correlates them). The window is chosen per centre by the Intersection of
Confidence Intervals rule (Goldenshluger & Nemirovski 1997; Katkovnik 1999): the largest h
such that the intervals [â_h' − Γ sd_h', â_h' + Γ sd_h'] of all h' ≤ h still intersect,
Γ = `GAMMA`. Near a corner the larger windows' estimates are biased out of the smaller
windows' intervals and the window stays short; on a plate it grows to ±96 centres.

Evidence (development seeds 7100–7117, 2 frames × 18 conditions of
`experiments/robust_extraction.py`, horizontal / vertical, pooled): the linked path alone
scored median 0.059 / 0.088 mm, p95 0.223 / 0.427 mm, gross 0.00 / 0.24 %; smoothed
(quadratic, Γ 2, c 4, h up to 96) median 0.041 / 0.051 mm, p95 0.203 / 0.276 mm, gross
0.00 / 0.06 % (see `cslx.segmentation.robust` for the held-out figures). Local lines instead
of quadratics: 0.041 / 0.063 mm (lines up to ±64: 0.035 / 0.085 mm — the vertical stripe's
path is curved by the lens distortion). A shorter smoothing along the stripe (3 / 4 px) with
this path smoothing lost detection (99.61 / 99.68 % horizontal) for no better median; a
correction of the curvature bias of the smoothing along the stripe (c''σ²/2 from the fit)
made every figure slightly worse. The p95 is left at the bead's corners, where the 6 px
smoothing along the stripe has already rounded the profile before the path is formed.

One-sided windows (`smooth_path(sided=True)`): the windows j − h … j and j … j + h are fitted
too, each side's window chosen by the ICI rule, and the three estimates are averaged with
weights 1 / sd² (the directional LPA-ICI of Katkovnik, Egiazarian & Astola 2006, fused as
if independent). A centre next to a corner, whose symmetric window must stay short, then
averages the plate on its own side; see `cslx.segmentation.refine.second_pass` for the
development figures.

Local lines (`smooth_path(lines=True)`, the linked detector's final smoothing,
`refine.LINES`; issue 11). At a window's centre a line's variance factor is 1 / n against the
quadratic's ≈ 9 / 4n, and at its end 4 / n against 9 / n, so lines average the plates and the
path's ends with a third to a half the variance. On a curve they are biased, and the vertical
stripe is curved along its whole length: it runs ≈ 155 px off the image centre and the lens
distortion bends it (second difference 0.065 px at lag 24, development frames; the
horizontal stripe, near the centre row, ≤ 0.005). So the lines are fitted to the centres
less k m², k = κ/2 of the quadratic through ±`CURVATURE_HALF` centres (`_curvature`): the
path's slowly varying bend comes from the long window, the value and slope from the ICI's
window. For every side the ICI rule chooses the lines' window as the quadratics', and their
estimates join the inverse-variance mean. Where the tail was (development seeds 7100–7117,
frames 0–2, 54 frames; errors > 0.1 mm, `experiments.robust_extraction`'s centres, H / V): 31
/ 15 % on the bends of the true path (second difference at lag 5 > 0.1 px; 5 / 3 % of the
centres; the first pass's rounding of the toes leaks through `refine.refine_centres`: 0.17 px
towards the chord at the sharpest bends, none when re-measured around the true path), 45 /
43 % within 1–80 centres of a bend (the bead's caps and the plates next to it), the rest
farther or in frames without a bend; 4 / 13 % within 12 centres of the image border (the
vertical stripe's top end, mostly cross scenes where it runs over the second weld). Mostly
slowly varying error (a 21-centre running mean keeps 70–90 % of its RMS), not a bias. Development
frames (same 54, H / V median / p95 mm, detection and gross unchanged: 100 / 99.90 %, 0.014 /
0.042 %): quadratics only 0.0292 / 0.1338, 0.0321 / 0.1434; with lines, k from ±64 / 256 /
512 (used) / 1024: 0.0308 / 0.1393, 0.0364 / 0.1498; 0.0278 / 0.1327, 0.0317 / 0.1346; 0.0269
/ 0.1294, 0.0303 / 0.1353; 0.0265 / 0.1287, 0.0303 / 0.1353 (the curvature of a short window
is too noisy: its error grows with the line's h²); plain lines (k = 0) on all three sides:
0.0233 / 0.1264, 0.0389 / 0.1472, one-sided only: 0.0276 / 0.1290, 0.0379 / 0.1575 (the
vertical stripe's bend). By frames (±512): 0–1 0.0297 / 0.1336, 0.0312 / 0.1398 → 0.0272 /
0.1255, 0.0284 / 0.1321; 2: 0.0283 / 0.1346, 0.0346 / 0.1495 → 0.0262 / 0.1360, 0.0340 /
0.1424; vertical centres within 12 rows of the border p95 0.254 → 0.208 mm. The toes are not
helped (sharpest bends 0.17 → 0.18 px towards the chord). Flat wall (seeds 41–46): RMS
smaller in 24 of 24 frame-stripes (worst 0.064 → 0.056 px), none beyond 0.5 px. With the
lines, the second pass's correlation c (`refine.REFINE_CORRELATION`) 6 → 8 / 10 (all 54
frames): 0.0269 / 0.1285, 0.0290 / 0.1342 and 0.0271 / 0.1290, 0.0283 / 0.1339; c 8 (used),
frames 0–1 / 2: vertical median 0.0284 → 0.0277, 0.0340 → 0.0326, p95 0.1321 → 0.1317,
0.1424 → 0.1385, horizontal within 0.0003 mm; flat wall RMS smaller in 24 of 24 again,
worst 0.050 px. Also tried: the lines in the first pass's
smoothing as well (`robust._finish`, c 6): 0.0268 / 0.1287, 0.0302 / 0.1358, no gain.
Cost: one smoothing 2.8 → 5.0 ms (640 centres), 2.1 → 3.7 ms (480), two per stripe
(`refine.LOCAL_WEIGHTS`; jitted, median of 15 interleaved, load ≈ 8 on 2 cores).

Pure JAX (the moments of all windows in one matrix product, closed-form 3×3 inverse),
jit- and vmap-able; ≈ 1 ms per path on the development CPU.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
from jax import lax

__all__ = ["CORRELATION", "GAMMA", "HALVES", "smooth_path"]

#: Half windows (centres) of the local quadratics, shortest first.
HALVES = (2, 4, 8, 16, 32, 64, 96)
#: Width Γ of the confidence intervals of the ICI rule (in standard deviations).
GAMMA = 2.0
#: Neighbouring centres that share one noise value (variance inflation of a window mean).
CORRELATION = 4.0
#: Half window (centres) of the quadratic whose curvature the local lines take
#: (`smooth_path(lines=True)`, module docstring "Local lines").
CURVATURE_HALF = 512


def _curvature(pos, valid, support, half: int, weights=None):
    """k = κ/2 (px per centre²), κ the second derivative of the least-squares quadratic
    through the `support` centres within ±`half` (weighted by `weights`; the last row of the
    closed-form 3×3 inverse), 0 where it is not determined."""
    w = support.astype(pos.dtype)
    if weights is not None:
        w = w * weights.astype(pos.dtype)
    y = jnp.where(valid, pos, 0.0)
    (s0, s1, s2, s3, s4), (t0, t1, t2) = (a[0] for a in _moments(w, y, (half,), 0))
    _, _, c02, det = _cofactors(s0, s1, s2, s3, s4)
    ok = valid & (s0 >= 5) & (det > 1e-6 * s0**3)
    a2 = (c02 * t0 + (s1 * s2 - s0 * s3) * t1 + (s0 * s2 - s1 * s1) * t2) / jnp.where(ok, det, 1.0)
    return jnp.where(ok, a2 / half**2, 0.0)


def _kernels(halves, side: int = 0) -> np.ndarray:
    """(2·P, 1, 2·h_max + 1) correlation kernels (m/h)^p on |m| ≤ h (side 0; side −1: only
    −h ≤ m ≤ 0, side 1: only 0 ≤ m ≤ h): first the five powers 0–4 of every window (applied
    to the weights), then the powers 0–2 (to weights × values), padded with zero kernels to
    P = 5 per window each."""
    r = max(halves)
    m = np.arange(-r, r + 1, dtype=float)
    first, second = [], []
    for h in halves:
        inside = (np.abs(m) <= h) & (side * m >= 0)
        first += [np.where(inside, (m / h) ** p, 0.0) for p in range(5)]
        second += [np.where(inside, (m / h) ** p, 0.0) for p in range(3)]
    second += [np.zeros_like(m)] * (len(first) - len(second))
    return np.stack(first + second)[:, None, :]


def _moments(w, y, halves, side: int = 0):
    """Σ_{m=−h..h} w[j+m] (m/h)^p (p ≤ 4) and Σ w[j+m] (y[j+m] − y[j]) (m/h)^p (p ≤ 2),
    zero padded, for every window, in the windows' own coordinates and relative to the
    centre's own value (float32-safe: the sums of y ≈ 300 px lost ≈ 1e-5 px to rounding,
    enough to flip a window choice between a batched and a single call). The (N, 2r + 1)
    windows times the kernels, a matrix product (XLA's CPU grouped convolution took ≈ 25 ms
    for the 10 windows up to ±256 of the second pass, three sides). Returns
    ((H, 5, N), (H, 3, N))."""
    r, n_h = max(halves), len(halves)
    kernel = jnp.asarray(_kernels(halves, side)[:, 0, :], w.dtype)  # (2·5H, 2r + 1)
    n = w.shape[-1]
    rows = jnp.arange(n)[:, None] + jnp.arange(2 * r + 1)[None, :]  # (N, 2r + 1)
    ww = jnp.pad(w, (r, r))[rows]
    dy = ww * (jnp.pad(y, (r, r))[rows] - y[:, None])
    half = 5 * n_h
    s = jnp.einsum("nm,km->kn", ww, kernel[:half], precision="highest")
    t = jnp.einsum("nm,km->kn", dy, kernel[half : half + 3 * n_h], precision="highest")
    return s.reshape(n_h, 5, -1), t.reshape(n_h, 3, -1)


def _counts(support, halves, side: int = 0):
    """(H, N) number of `support` centres in every window (`_kernels`' extent), by cumsum."""
    n = support.shape[0]
    j = jnp.arange(n)
    c = jnp.concatenate([jnp.zeros(1, jnp.int32), jnp.cumsum(support.astype(jnp.int32))])
    rows = []
    for h in halves:
        lo = jnp.clip(j - h if side <= 0 else j, 0, n - 1)
        hi = jnp.clip(j + h if side >= 0 else j, 0, n - 1)
        rows.append(c[hi + 1] - c[lo])
    return jnp.stack(rows)


def _cofactors(s0, s1, s2, s3, s4):
    """The first row (c00, c01, c02) of the adjugate of the local quadratic's moment matrix
    M = [s_{i+j}] and det M (M is symmetric: the first column too)."""
    c00 = s2 * s4 - s3 * s3
    c01 = s2 * s3 - s1 * s4
    c02 = s1 * s3 - s2 * s2
    return c00, c01, c02, s0 * c00 + s1 * c01 + s2 * c02


def _window_fits(pos, valid, support, halves, side: int = 0, weights=None, lines=False, curv=None):
    """Value at each valid centre of the local quadratic through the `support` centres within
    ±h (every h of `halves`), weighted by `weights` (None: uniform), and its variance
    factor (M⁻¹)₀₀ for a centre of weight 1: [(estimate, factor)], each (H, N), NaN / inf
    where the window holds fewer than 5 support centres. With `lines`, a second pair from
    the same moments: the local line (3 centres) through y − k m², `curv` (N,) giving k per
    centre (None: 0)."""
    w = support.astype(pos.dtype)
    if weights is not None:
        w = w * weights.astype(pos.dtype)
    y = jnp.where(valid, pos, 0.0)
    moments = _moments(w, y, halves, side)
    (s0, s1, s2, s3, s4), (t0, t1, t2) = (jnp.moveaxis(a, 1, 0) for a in moments)
    count = s0 if weights is None else _counts(support, halves, side)
    c00, c01, c02, det = _cofactors(s0, s1, s2, s3, s4)
    ok = valid & (count >= 5) & (det > 1e-6 * s0**3)
    safe = jnp.where(ok, det, 1.0)
    est = y + (c00 * t0 + c01 * t1 + c02 * t2) / safe
    fits = [(jnp.where(ok, est, jnp.nan), jnp.where(ok, c00 / safe, jnp.inf))]
    if lines:  # (M⁻¹)₀₀ = s2 / (s0 s2 − s1²)
        det = s0 * s2 - s1 * s1
        ok = valid & (count >= 3) & (det > 1e-6 * s0 * jnp.maximum(s2, 1e-12))
        safe = jnp.where(ok, det, 1.0)
        if curv is not None:  # through y − k m²: in the window's u = m/h, k h² u²
            a = curv[None, :] * jnp.asarray(np.square(halves), pos.dtype)[:, None]
            t0, t1 = t0 - a * s2, t1 - a * s3
        est = y + (s2 * t0 - s1 * t1) / safe
        fits.append((jnp.where(ok, est, jnp.nan), jnp.where(ok, s2 / safe, jnp.inf)))
    return fits


def smooth_path(
    pos,
    valid,
    scatter,
    *,
    support=None,
    gamma=GAMMA,
    correlation=CORRELATION,
    halves=HALVES,
    sided: bool = False,
    weights=None,
    lines: bool = False,
    curvature_half: int = CURVATURE_HALF,
):
    """Local-quadratic path smoothing with per-centre windows by the ICI rule (module docstring).

    Args:
        pos: (N,) centres along the search axis (any value where not valid).
        valid: (N,) bool.
        scatter: the path's robust std about its local line (px, scalar).
        support: (N,) bool, the centres the fits pass through (default `valid`); a valid
            centre outside it gets the value of the fit through its neighbours (e.g. near
            the image border, where the smoothing along the stripe is biased).
        gamma, correlation: Γ and c of the module docstring.
        halves: half windows, shortest first (static).
        sided: also fit one-sided windows (j − h … j and j … j + h), choose each side's
            window by the ICI rule too, and return the inverse-variance mean of the three
            estimates (static; the linked detector's second pass,
            `cslx.segmentation.refine.second_pass`).
        weights: (N,) per-centre weights of the fits (relative inverse variances, ≈ 1 for
            a typical centre; None: uniform); the factor is then that of a centre of
            weight 1 (`refine.LOCAL_WEIGHTS`).
        lines: also fit local lines on every side's windows (through the centres less
            k m², k = κ/2 of the quadratic through ±`curvature_half` centres; 0: none),
            choose their windows by the ICI rule and add them to the inverse-variance mean
            (static; module docstring, "Local lines").

    Returns:
        (smoothed pos, factor): factor (N,) ≤ 1 is the ratio of the chosen estimate's std to
        one centre's, √min(c (M⁻¹)₀₀, 1) (1 where nothing was averaged; with `sided` that of
        the combination, as if the three were independent); invalid centres are returned as
        they were.
    """
    support = valid if support is None else support & valid
    sides = (0, -1, 1) if sided else (0,)
    num = den = 0.0
    k = None
    if lines and curvature_half:
        k = _curvature(pos, valid, support, curvature_half, weights)
    # each side's moments once, for its quadratics and its lines
    per_side = [_window_fits(pos, valid, support, halves, s, weights, lines, k) for s in sides]
    fits = [
        _ici(est, var, valid, support, scatter, gamma, correlation)
        for order in range(len(per_side[0]))  # quadratics first, then lines
        for est, var in (side_fits[order] for side_fits in per_side)
    ]
    for chosen, f, use in fits:
        w = jnp.where(use, 1.0 / jnp.maximum(f, 1e-3) ** 2, 0.0)
        num = num + w * jnp.where(use, chosen, 0.0)
        den = den + w
    use = valid & (den > 0)
    out = num / jnp.where(use, den, 1.0)
    return jnp.where(use, out, pos), jnp.where(use, jnp.sqrt(1.0 / jnp.where(use, den, 1.0)), 1.0)


def _ici(est, var, valid, support, scatter, gamma, correlation):
    """The ICI rule over one side's window fits (`_window_fits`' (estimate, factor), each
    (H, N); `smooth_path`): (estimate, its std factor, whether a window was usable), each
    (N,)."""
    # One centre's own noise bounds a fit through it; an extrapolation (a centre outside the
    # support) can be worse than that.
    factor = jnp.sqrt(jnp.where(support, jnp.minimum(correlation * var, 1.0), correlation * var))
    good = jnp.isfinite(est)
    sd = lax.stop_gradient(scatter) * factor
    lo = lax.cummax(jnp.where(good, est - gamma * sd, -jnp.inf), axis=0)
    hi = lax.cummin(jnp.where(good, est + gamma * sd, jnp.inf), axis=0)
    # The usable windows' intervals up to i intersect; keep the longest usable such window.
    run = jnp.cumprod((lo <= hi).astype(jnp.int32), axis=0).astype(bool) & good
    index = jnp.arange(est.shape[0])[:, None]
    best = jnp.max(jnp.where(run, index, -1), axis=0)
    pick = jnp.maximum(best, 0)[None]
    chosen = jnp.take_along_axis(jnp.where(good, est, 0.0), pick, 0)[0]
    f = jnp.take_along_axis(factor, pick, 0)[0]
    use = valid & (best >= 0)
    return chosen, jnp.where(use, f, 1.0), use
