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


def _window_fits(pos, valid, support, halves, side: int = 0, weights=None):
    """Value at each valid centre of the local quadratic through the `support` centres within
    ±h (every h of `halves`), weighted by `weights` (None: uniform), and its variance
    factor (M⁻¹)₀₀ for a centre of weight 1: (estimate, factor), each (H, N), NaN / inf where
    the window holds fewer than 5 support centres."""
    w = support.astype(pos.dtype)
    if weights is not None:
        w = w * weights.astype(pos.dtype)
    y = jnp.where(valid, pos, 0.0)
    moments = _moments(w, y, halves, side)
    (s0, s1, s2, s3, s4), (t0, t1, t2) = (jnp.moveaxis(a, 1, 0) for a in moments)
    c00 = s2 * s4 - s3 * s3
    c01 = s2 * s3 - s1 * s4
    c02 = s1 * s3 - s2 * s2
    det = s0 * c00 + s1 * c01 + s2 * c02
    count = s0 if weights is None else _counts(support, halves, side)
    ok = valid & (count >= 5) & (det > 1e-6 * s0**3)
    safe = jnp.where(ok, det, 1.0)
    est = y + (c00 * t0 + c01 * t1 + c02 * t2) / safe
    return jnp.where(ok, est, jnp.nan), jnp.where(ok, c00 / safe, jnp.inf)


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

    Returns:
        (smoothed pos, factor): factor (N,) ≤ 1 is the ratio of the chosen estimate's std to
        one centre's, √min(c (M⁻¹)₀₀, 1) (1 where nothing was averaged; with `sided` that of
        the combination, as if the three were independent); invalid centres are returned as
        they were.
    """
    support = valid if support is None else support & valid
    sides = (0, -1, 1) if sided else (0,)
    num = den = 0.0
    fits = [
        _ici(pos, valid, support, scatter, gamma, correlation, halves, side, weights)
        for side in sides
    ]
    for chosen, f, use in fits:
        w = jnp.where(use, 1.0 / jnp.maximum(f, 1e-3) ** 2, 0.0)
        num = num + w * jnp.where(use, chosen, 0.0)
        den = den + w
    use = valid & (den > 0)
    out = num / jnp.where(use, den, 1.0)
    return jnp.where(use, out, pos), jnp.where(use, jnp.sqrt(1.0 / jnp.where(use, den, 1.0)), 1.0)


def _ici(pos, valid, support, scatter, gamma, correlation, halves, side, weights=None):
    """The ICI rule over the windows of one side (`smooth_path`): (estimate, its std factor,
    whether a window was usable), each (N,)."""
    est, var = _window_fits(pos, valid, support, halves, side, weights)  # (H, N)
    # One centre's own noise bounds a fit through it; an extrapolation (a centre outside the
    # support) can be worse than that.
    factor = jnp.sqrt(jnp.where(support, jnp.minimum(correlation * var, 1.0), correlation * var))
    good = jnp.isfinite(est)
    sd = lax.stop_gradient(scatter) * factor
    lo = lax.cummax(jnp.where(good, est - gamma * sd, -jnp.inf), axis=0)
    hi = lax.cummin(jnp.where(good, est + gamma * sd, jnp.inf), axis=0)
    # The usable windows' intervals up to i intersect; keep the longest usable such window.
    run = jnp.cumprod((lo <= hi).astype(jnp.int32), axis=0).astype(bool) & good
    index = jnp.arange(len(halves))[:, None]
    best = jnp.max(jnp.where(run, index, -1), axis=0)
    pick = jnp.maximum(best, 0)[None]
    chosen = jnp.take_along_axis(jnp.where(good, est, 0.0), pick, 0)[0]
    f = jnp.take_along_axis(factor, pick, 0)[0]
    use = valid & (best >= 0)
    return chosen, jnp.where(use, f, 1.0), use
