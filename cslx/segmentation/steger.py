"""Steger's sub-pixel line detector (IEEE PAMI 20(2), 1998), one centre per column or row.

Section 3.3 of the paper locates the stripe centres with Steger's method on the MED output.
For each pixel the image is smoothed with Gaussian derivatives of scale σ, the Hessian

    H = [[r_vv, r_uv], [r_uv, r_uu]]

is diagonalised in closed form, and its most negative eigenvalue λ (a bright ridge has
λ ≪ 0) gives the unit normal n = (n_v, n_u) across the line. The second-order Taylor
expansion along n puts the ridge at the offset

    t = −(n_v r_v + n_u r_u) / λ                                   (Steger, eq. (17))

and the pixel is a line point when |t n_v| ≤ ½ and |t n_u| ≤ ½ (the point lies in the
pixel; cslx defaults to 0.6, see `max_offset`) with strength −λ above a threshold.

The paper's stripes are sampled one centre per image column (horizontal stripe) or per
row (vertical stripe), so cslx reports, for each column, the row where the local ridge line
crosses that column's centre: v* = v + t / n_v (moving along the tangent from Steger's point
p = (v + t n_v, u + t n_u) back to column u; exact for straight lines, and it keeps the
column index exact so that ground truth per column applies). Among the accepted points of a
column the strongest wins, found by one integer max reduction (`cslx.reductions`) and read
by masked sums rather than `jnp.argmax` + gather (docs/metrics.md, performance notes); of
equal ones the first.

σ follows Steger's condition for a bar profile of half-width w: σ ≥ w/√3
(`sigma_for_width`). The separable Gaussian derivative filters are written as sums of
shifted slices with folded symmetric/antisymmetric taps, reflect boundary, identical to
`scipy.ndimage.gaussian_filter(..., order=..., mode="reflect", truncate=4.0)`. The Hessian
pads the image once in both axes and filters valid parts (`_filter_padded`): issue 13, the
pipeline's tracking mode with MED in the bands 14.73 → 13.87 ms, the tracker's tracking
mode 7.29 → 6.68 ms, `Tracker.step` 8.52 → 8.05 ms (experiments.ab_tracking against the
per-pass padding, 300 interleaved frames each, load 4.4–6.9; outputs identical). Tried
there and not kept (no gain beyond the noise on the 64×640 and 480×128 bands): the
selection as one column maximum and one masked sum, 1/√ for `lax.rsqrt`, XLA's
convolution (5.6 ms for the first pass alone), a banded matrix product (0.34 against
0.18 ms).

Strength threshold: a point is kept when −λ ≥ `threshold` × (the frame's largest −λ among
geometrically valid ridge points), −λ ≥ `snr` × (mean |λ| over the frame, the noise level of
the strength map) and −λ ≥ `min_strength` (absolute, in intensity/px²). The first two are
independent of the image's scale (MED output has an arbitrary scale); `snr` also rejects
frames without a stripe.

Everything is pure JAX on one frame, jit-compiled at the public entry points, vmap-able
over frames and differentiable with respect to the image (`pos` is NaN where `valid` is
False: mask before differentiating a loss).
"""

from __future__ import annotations

import functools
import math
from typing import NamedTuple

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax
from jaxtyping import Array, ArrayLike, Bool, Float

from ..reductions import first_argmax

__all__ = [
    "Centres",
    "gaussian_derivative",
    "sigma_for_width",
    "steger_centres",
    "steger_cross",
    "TRUNCATE",
]

#: Gaussian kernels are cut at TRUNCATE·σ, as `scipy.ndimage.gaussian_filter` does.
TRUNCATE = 4.0


class Centres(NamedTuple):
    """Stripe centres sampled once per image column (horizontal stripe) or row (vertical).

    Attributes:
        pos: (N,) sub-pixel coordinate along the search axis: the row v of each column for a
            horizontal stripe, the column u of each row for a vertical stripe (OpenCV pixel
            convention, origin at the centre of the top-left pixel). NaN where not valid.
        valid: (N,) True where a centre was found.
        strength: (N,) detector response of the chosen point (0 where not valid); for
            Steger −λ in intensity/px², for the baselines the peak height above background.
        sigma: (N,) optional predicted standard deviation of `pos` (px) from the image noise
            and the Hessian (`cslx.segmentation.ridges`); None where the method has none.
        saturated: (N,) optional flag: the centre lies on a clipped (saturated) core and was
            taken from the plateau's edges; None where the method does not check.
    """

    pos: Float[Array, " n"]
    valid: Bool[Array, " n"]
    strength: Float[Array, " n"]
    sigma: Float[Array, " n"] | None = None
    saturated: Bool[Array, " n"] | None = None


def sigma_for_width(width: float) -> float:
    """Smallest Steger scale for a bright bar stripe of full width `width` pixels.

    Steger's condition for a bar profile of half-width w is σ ≥ w/√3 (one maximum of the
    smoothed profile, hence one centre). With w = width/2 this is σ = width / (2√3).
    For a Gaussian profile of standard deviation s the equivalent bar (same second moment)
    has width 2√3 s, so σ = s: pass `width = 2 * math.sqrt(3) * s`. Floors at 0.7 px, below
    which the sampled Gaussian derivative filters stop being accurate.
    """
    if not width > 0:
        raise ValueError(f"stripe width must be positive, got {width!r}")
    return max(width / (2.0 * math.sqrt(3.0)), 0.7)


def _taps(sigma: float, order: int) -> np.ndarray:
    """Gaussian (derivative) kernel g(x), x = 0..r, exactly as scipy.ndimage builds it."""
    if not sigma > 0:
        raise ValueError(f"sigma must be positive, got {sigma!r}")
    r = int(TRUNCATE * sigma + 0.5)
    x = np.arange(-r, r + 1, dtype=np.float64)
    phi = np.exp(-0.5 * x**2 / sigma**2)
    phi /= phi.sum()
    poly = {0: np.ones_like(x), 1: -x / sigma**2, 2: x**2 / sigma**4 - 1 / sigma**2}[order]
    return (poly * phi)[r:]


def _filter_axis(x: Array, sigma: float, orders: tuple[int, ...], axis: int) -> list[Array]:
    """Gaussian derivatives of several orders along one axis, sharing the shifted slices.

    out[i] = Σ_k g(k) x[i − k] (a convolution, scipy's convention) with the reflect boundary
    (d c b a | a b c d | d c b a). Even kernels fold as g(k)(x[i−k] + x[i+k]), odd ones as
    g(k)(x[i−k] − x[i+k]).
    """
    r = _radius(sigma)
    pad = [(0, 0)] * x.ndim
    pad[axis] = (r, r)
    return _filter_padded(jnp.pad(x, pad, mode="symmetric"), sigma, orders, axis)


def _radius(sigma: float) -> int:
    return len(_taps(sigma, 0)) - 1


def _filter_padded(xp: Array, sigma: float, orders: tuple[int, ...], axis: int) -> list[Array]:
    """`_filter_axis` of an array already padded by the kernel radius r on both ends of
    ``axis`` (the output is 2r shorter there: the valid part)."""
    taps = {o: _taps(sigma, o) for o in orders}
    r = len(taps[orders[0]]) - 1
    n = xp.shape[axis] - 2 * r

    def shifted(k: int) -> Array:
        return lax.slice_in_dim(xp, r + k, r + k + n, axis=axis)

    centre = shifted(0)
    out = {
        o: (centre * float(taps[o][0]) if o % 2 == 0 else jnp.zeros_like(centre)) for o in orders
    }
    even = [o for o in orders if o % 2 == 0]
    odd = [o for o in orders if o % 2 == 1]
    for k in range(1, r + 1):
        before, after = shifted(-k), shifted(k)
        if even:
            s = before + after
            for o in even:
                out[o] = out[o] + float(taps[o][k]) * s
        if odd:
            d = before - after
            for o in odd:
                out[o] = out[o] + float(taps[o][k]) * d
    return [out[o] for o in orders]


def gaussian_derivative(
    image: Float[Array, "h w"], sigma: float, order: tuple[int, int] = (0, 0)
) -> Float[Array, "h w"]:
    """Gaussian-smoothed partial derivative ∂^(o_v + o_u) / ∂v^o_v ∂u^o_u of an image.

    Same values as `scipy.ndimage.gaussian_filter(image, sigma, order=order)` (reflect
    boundary, truncate 4.0); orders 0, 1, 2 per axis. `sigma` in pixels (static).
    """
    (a,) = _filter_axis(jnp.asarray(image), sigma, (order[0],), 0)
    (b,) = _filter_axis(a, sigma, (order[1],), 1)
    return b


class _Ridge(NamedTuple):
    strength: Array  # −λ, positive on bright ridges
    scale: Array  # mean |λ| over the frame: the noise level of the strength map
    nv: Array
    nu: Array
    t: Array
    geometric: Array  # λ < 0 and the Taylor extremum lies inside the pixel


def _ridge(image: Array, sigma: float, max_offset) -> _Ridge:
    """Per-pixel Hessian eigen-decomposition and Steger offset, closed form and grad-safe."""
    # The image is padded once in both axes: filtering the reflected columns down axis 0
    # gives the reflected columns of the filtered image, so the second pass needs no padding
    # of its three inputs (the same values bit for bit; issue 13: the six concatenations
    # of the second pass's reflect padding cost the 480×128 band of columns ≈ 0.3 ms).
    r = _radius(sigma)
    xp = jnp.pad(image, r, mode="symmetric")
    a0, a1, a2 = _filter_padded(xp, sigma, (0, 1, 2), 0)
    ru, ruu = _filter_padded(a0, sigma, (1, 2), 1)
    rv, ruv = _filter_padded(a1, sigma, (0, 1), 1)
    (rvv,) = _filter_padded(a2, sigma, (0,), 1)

    half_diff = 0.5 * (rvv - ruu)
    q = half_diff**2 + ruv**2
    q_pos = q > 0
    s = jnp.where(q_pos, jnp.sqrt(jnp.where(q_pos, q, 1.0)), 0.0)
    lam = 0.5 * (rvv + ruu) - s  # the most negative eigenvalue
    # Eigenvector of λ from either row of (H − λI); pick the better-conditioned one.
    use_first = half_diff >= 0
    ev = jnp.where(use_first, ruv, lam - ruu)
    eu = jnp.where(use_first, lam - rvv, ruv)
    norm2 = ev**2 + eu**2
    ok = norm2 > 0
    inv = jnp.where(ok, lax.rsqrt(jnp.where(ok, norm2, 1.0)), 0.0)
    nv = jnp.where(ok, ev * inv, 1.0)
    nu = jnp.where(ok, eu * inv, 0.0)
    neg = lam < 0
    t = jnp.where(neg, -(nv * rv + nu * ru) / jnp.where(neg, lam, -1.0), 0.0)
    geometric = neg & (jnp.abs(t * nv) <= max_offset) & (jnp.abs(t * nu) <= max_offset)
    scale = lax.stop_gradient(jnp.mean(jnp.abs(lam)))
    return _Ridge(-lam, scale, nv, nu, t, geometric)


def _select(
    ridge: _Ridge, axis: int, threshold, min_strength, snr, min_cos: float, strongest=None
) -> Centres:
    """Strongest accepted ridge point per column (axis 0) or row (axis 1), at the crossing.

    A column's candidates are its geometric, steep enough ridge points of positive strength
    ≥ ``min_strength``; the strongest is found by `cslx.reductions.first_argmax` (one
    integer max reduction, no equality with a recomputed maximum: module docstring there).
    The other thresholds are monotone in the strength, so they apply to that strongest
    candidate: the column's accepted point is it, or none. ``strongest`` (None: the largest
    of the columns' maxima, the frame's strongest ridge point of this axis) sets the
    relative threshold.
    """
    n_along = ridge.nv if axis == 0 else ridge.nu
    steep_ok = jnp.abs(n_along) >= min_cos
    candidate = ridge.geometric & steep_ok & (ridge.strength >= min_strength) & (ridge.strength > 0)
    top, found = first_argmax(ridge.strength, axis, candidate)
    index = lax.broadcasted_iota(jnp.int32, ridge.t.shape, axis)
    chosen = index == jnp.expand_dims(top, axis)
    safe_n = jnp.where(steep_ok, n_along, 1.0)
    offset = ridge.t / safe_n  # to the crossing of the local line with the column/row
    best = jnp.sum(jnp.where(chosen, ridge.strength, 0.0), axis=axis)
    at = jnp.sum(jnp.where(chosen, offset, 0.0), axis=axis)
    if strongest is None:
        strongest = lax.stop_gradient(jnp.max(jnp.where(found, best, 0.0)))
    valid = found & (best >= threshold * strongest) & (best >= snr * ridge.scale)
    pos = jnp.where(valid, top.astype(at.dtype) + at, jnp.nan)
    return Centres(pos, valid, jnp.where(valid, best, 0.0))


def _strongest(ridge: _Ridge, min_cos: float, axes: tuple[int, ...]) -> Array:
    ok = ridge.geometric & functools.reduce(
        jnp.logical_or, [jnp.abs(ridge.nv if a == 0 else ridge.nu) >= min_cos for a in axes]
    )
    return lax.stop_gradient(jnp.max(jnp.where(ok, ridge.strength, 0.0)))


def _check_image(image) -> Array:
    image = jnp.asarray(image)
    if image.ndim != 2:
        raise ValueError(f"expected a 2-D monochrome image (H, W), got shape {image.shape}")
    if not jnp.issubdtype(image.dtype, jnp.floating):
        image = image.astype(jnp.result_type(float))
    return image


@functools.partial(jax.jit, static_argnames=("sigma", "axis", "max_angle_deg"))
def _steger_centres(image, threshold, min_strength, snr, max_offset, *, sigma, axis, max_angle_deg):
    ridge = _ridge(image, sigma, max_offset)
    min_cos = math.cos(math.radians(max_angle_deg))
    return _select(ridge, axis, threshold, min_strength, snr, min_cos)


def steger_centres(
    image: Float[ArrayLike, "h w"],
    *,
    sigma: float,
    axis: int = 0,
    threshold: float = 0.1,
    min_strength: float = 0.0,
    snr: float = 5.0,
    max_offset: float = 0.6,
    max_angle_deg: float = 60.0,
) -> Centres:
    """Sub-pixel stripe centres by Steger's method, one per column (axis=0) or row (axis=1).

    Args:
        image: (H, W) monochrome image, bright stripe on a darker background; integer
            images are converted to the default float dtype, float dtypes are kept.
        sigma: Gaussian scale in pixels (static; see `sigma_for_width`).
        axis: 0 for a horizontal stripe (one centre per column, `pos` is the row v, N = W),
            1 for a vertical stripe (one per row, `pos` is the column u, N = H).
        threshold: relative strength threshold in [0, 1]: keep points with −λ at least this
            fraction of the frame's strongest ridge point.
        min_strength: absolute floor on −λ (intensity units / px²).
        snr: scale-free noise floor: keep points with −λ ≥ snr × mean |λ| over the frame.
            On pure white noise the strongest ridge point of a column is ≈ 3.5 (≤ 5.6) times
            that mean, so the default 5 rejects nearly all noise-only columns and frames.
        max_offset: acceptance |t n_v|, |t n_u| ≤ max_offset. Steger's value is 0.5; the
            default 0.6 covers the Taylor overshoot (≈ d³/σ_tot²) of a centre on a pixel
            border, which would otherwise be rejected by both neighbours and lose the column.
        max_angle_deg: largest angle between the stripe and the image axis it runs along
            (static); steeper ridge points (e.g. the other stripe of a cross) are ignored.

    Returns:
        `Centres` (pos, valid, strength) of length W (axis=0) or H (axis=1).
    """
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (horizontal stripe) or 1 (vertical), got {axis!r}")
    image = _check_image(image)
    return _steger_centres(
        image,
        jnp.asarray(threshold, image.dtype),
        jnp.asarray(min_strength, image.dtype),
        jnp.asarray(snr, image.dtype),
        jnp.asarray(max_offset, image.dtype),
        sigma=float(sigma),
        axis=axis,
        max_angle_deg=float(max_angle_deg),
    )


@functools.partial(jax.jit, static_argnames=("sigma", "max_angle_deg"))
def _steger_cross(image, threshold, min_strength, snr, max_offset, *, sigma, max_angle_deg):
    ridge = _ridge(image, sigma, max_offset)
    min_cos = math.cos(math.radians(max_angle_deg))
    strongest = _strongest(ridge, min_cos, (0, 1))
    return (
        _select(ridge, 0, threshold, min_strength, snr, min_cos, strongest),
        _select(ridge, 1, threshold, min_strength, snr, min_cos, strongest),
    )


def steger_cross(
    image: Float[ArrayLike, "h w"],
    *,
    sigma: float,
    threshold: float = 0.1,
    min_strength: float = 0.0,
    snr: float = 5.0,
    max_offset: float = 0.6,
    max_angle_deg: float = 45.0,
) -> tuple[Centres, Centres]:
    """Both stripes of a cross from one Hessian: (horizontal per column, vertical per row).

    Same arguments as `steger_centres`; the relative threshold refers to the strongest ridge
    point of either stripe. The default `max_angle_deg` of 45° splits the ridge points
    between the two stripes.
    """
    image = _check_image(image)
    return _steger_cross(
        image,
        jnp.asarray(threshold, image.dtype),
        jnp.asarray(min_strength, image.dtype),
        jnp.asarray(snr, image.dtype),
        jnp.asarray(max_offset, image.dtype),
        sigma=float(sigma),
        max_angle_deg=float(max_angle_deg),
    )
