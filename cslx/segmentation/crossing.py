"""A cross turned against the image axes: centres the other stripe or the border spoil.

The linked detector measures each column's profile (`cslx.segmentation.ridges`, step 1, and
`cslx.segmentation.refine`): the other stripe of the cross, when it runs along the column,
is constant there and adds nothing to the profile's derivatives. When the cross is turned
against the image axes (a rig whose projector is not aligned with the camera), the other
stripe crosses each column at an angle: within a few columns of the crossing its light lies
on one side of this stripe's profile and pulls the centre towards it. A stripe that leaves
the frame across its search axis meets a second problem at the border: its last profiles are
cut, and the smoothed image's edge makes a ridge along the border that the path followed.

**The crossing, found geometrically** (`other_stripe`). The other stripe is a straight bright
line crossing the path. A band of the image along the path (offsets o across it from
`INNER` σ_t to `OUTER` σ_t + 6 px on each side, σ_t the smoothed profile's width) is filtered
for ridges running across the path (−∂²/∂j² of a Gaussian of `RIDGE_SIGMA` along it) and
summed along every line j = j_c + slope · o, separately above and below the path (a Radon
transform of the band, `N_SLOPES` slopes up to `MAX_SLOPE` centres per px across, offsets
every `BAND_STEP` px, as phase ramps on the FFT of each offset's column). Cost, 640×480,
load 3.9: 12–13 ms per stripe (by gathers: 19 ms, 42 ms with 1 px steps and 49 slopes). The
other stripe is the line whose weaker side is strongest; it counts where that side exceeds
`LINE_SHARE` × the path's own ridge response and `LINE_NOISE` × the line sums' robust noise.
The slope says the angle: for a cross turned by a, −tan a / (1 + tan² a) (0 aligned, −0.47
at 35°). Centres within |slope| · (`REACH_WIDTHS` σ_t + `REACH_PX`) + `REACH_PAD` of j_c
(where the other stripe is inside the profile's reach, off-centre) are interpolated; an
aligned crossing (|slope| < `MIN_SLOPE`) is not: it pulls nothing. A synthetic cross turned
by 5 / 10 / 15 / 20 / 30° (tests/segmentation/test_crossing.py's frame): largest error
within ±20 columns 0.017 / 0.080 / 0.154 / 0.229 / 1.30 px measured → 0.017 / 0.012 /
0.018 / 0.008 / 0.00 px; `REACH_WIDTHS` 2.5 left 0.47 px at 30° (the fits through the
biased columns just outside). On every audit frame (seed 7400 + condition, 12 conditions ×
2 frames, both stripes) j_c lies within 6 centres of the crossing of the two extracted paths.

**The border** (`inside`, `interpolated`). Centres closer than `EDGE` px to the border across
the stripe are dropped (audit, 35° turned cross, sunny: 16–17 false centres a frame at
u ≈ 639, and the path bent onto them, 1.2–2.9 px off over 10 rows), and those within
`CUT_WIDTHS` σ_t of it are interpolated (their profile is cut). With
`cslx.segmentation.robust.BORDER` (on by default) a turned stripe's centres near the border
come back at the end from the fit through those inside (`border`).

The caller (`cslx.segmentation.robust`, step 7) excludes the flagged centres from the second
pass's measurement and gives them the value of the final path smoothing through their
neighbours (`refine.second_pass(interpolate=...)`). Evidence, and what was tried: the module
docstring of `experiments/ood_extraction.py`.

Pure JAX, jit-compiled.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["CUT_WIDTHS", "EDGE", "MIN_SLOPE", "REACH_WIDTHS", "inside", "interpolated",
           "other_stripe"]  # fmt: skip

#: A centre closer than this (px) to the image's border across the stripe is dropped.
EDGE = 1.5
#: Centres within this many σ_t of the border across the stripe are interpolated. Audit
#: (35° turned cross, seed 7406–7407): 2.5 σ_t extrapolated a saturated stripe (σ_t 9 px)
#: over 30 rows, 1.5 px off; 1.0: none.
CUT_WIDTHS = 1.0


def inside(pos, length: int):
    """(N,) True where a centre lies more than `EDGE` px inside the image across the stripe."""
    return (pos > EDGE) & (pos < length - 1 - EDGE)


def _sample(x, pos, offset):
    """x[j, pos_j + offset] by linear interpolation along axis 1 (clamped)."""
    m = x.shape[1]
    y = jnp.clip(pos + offset, 0.0, m - 1.0)
    i0 = jnp.clip(jnp.floor(y).astype(jnp.int32), 0, m - 2)
    f = y - i0
    j = jnp.arange(x.shape[0])
    return x[j, i0] * (1 - f) + x[j, i0 + 1] * f


#: Band around the path searched for the other stripe: offsets (px across) from `INNER` σ_t
#: to `OUTER` σ_t + 6 px on both sides.
INNER = 2.5
OUTER = 5.0
#: Slopes dj/do (centres per px across) of the other stripe tried: `N_SLOPES` up to
#: `MAX_SLOPE` (an orthogonal cross turned by any angle: |slope| ≤ 0.5; perspective: up to
#: 0.65 on the audit's frames).
MAX_SLOPE = 0.8
N_SLOPES = 33
#: Smoothing (centres) along the path of the band's ridge filter.
RIDGE_SIGMA = 1.5
#: The other stripe's line counts where its mean ridge response on each side exceeds
#: `LINE_SHARE` × the path's own (median) ridge response and `LINE_NOISE` × the band's noise.
LINE_SHARE = 0.25
LINE_NOISE = 6.0
#: Smallest |slope| whose crossing is interpolated (0.25 on the slopes' 0.05 grid: a cross
#: turned by ≥ 15°): an aligned crossing is constant along the profile and pulls nothing,
#: and the default rig's (|slope| 0–0.2 on the audit's frames) pulls ≤ 0.08 px (synthetic
#: cross at 10°); at 0.22 the development benchmark is unchanged.
MIN_SLOPE = 0.22
#: Centres within |slope| · (`REACH_WIDTHS` σ_t + `REACH_PX`) + `REACH_PAD` of the crossing
#: are interpolated.
REACH_WIDTHS = 4.0
REACH_PX = 2.0
REACH_PAD = 2.0
#: Half-height (px) of the band, its static bound, and the step (px) of its offsets.
BAND = 32
BAND_STEP = 2


def _ridge_along(b, sigma):
    """−∂²/∂j² of a Gaussian of `sigma` along axis 0 of b (ridges across j bright)."""
    r = int(math.ceil(4 * sigma))
    t = np.arange(-r, r + 1, dtype=float)
    g = np.exp(-0.5 * (t / sigma) ** 2)
    g /= g.sum()
    k = -(t**2 / sigma**4 - 1 / sigma**2) * g  # −g''
    k -= k.mean()
    kern = jnp.asarray(k, b.dtype)
    return jax.vmap(lambda c: jnp.convolve(c, kern, mode="same"), 1, 1)(b)


@functools.partial(jax.jit, static_argnames=("axis",))
def other_stripe(mono, pos, valid, width, *, axis: int):
    """The other stripe where it crosses the path: (j_c, slope, found, score).

    A band of the image around the path (offsets o across it, `INNER`…`OUTER` σ_t on
    each side) is filtered for ridges running across the path (−∂²/∂j² along it) and
    summed along every line j = j_c + slope · o (a Radon transform of the band): the
    other stripe of the cross is the best line, and it counts where each side's mean
    response exceeds `LINE_SHARE` × the path's own stripe's and `LINE_NOISE` × noise.
    """
    x = mono.T if axis == 0 else mono
    n, m = x.shape
    dtype = x.dtype
    j = jnp.arange(n)
    # the path, interpolated over its gaps (a bridged or missing stretch at the crossing)
    prev = jax.lax.cummax(jnp.where(valid, j, -1))
    nxt = jax.lax.cummin(jnp.where(valid, j, n), reverse=True)
    pp = jnp.where(prev >= 0, prev, nxt).clip(0, n - 1)
    nn = jnp.where(nxt < n, nxt, prev).clip(0, n - 1)
    p0 = jnp.nan_to_num(pos)
    span = jnp.maximum(nn - pp, 1).astype(dtype)
    p = jnp.where(valid, p0, p0[pp] + (j - pp) * (p0[nn] - p0[pp]) / span)
    lo = INNER * width
    hi = jnp.minimum(OUTER * width + 6.0, BAND)
    k_o = BAND  # static bound on the band's half-height
    offs = jnp.arange(-k_o, k_o + 1, BAND_STEP).astype(dtype)
    side = (jnp.abs(offs) >= lo) & (jnp.abs(offs) <= hi)
    band = jax.vmap(lambda o: _sample(x, p, o), out_axes=1)(offs)  # (N, O)
    inside_img = ((p[:, None] + offs[None, :]) >= 0) & ((p[:, None] + offs[None, :]) <= m - 1)
    r = _ridge_along(band, RIDGE_SIGMA)
    r = jnp.where(inside_img, r, 0.0)
    # the path's own stripe: ridge across o at o = 0 (its strength, for the share test)
    own_r = _ridge_along(jax.vmap(lambda o: _sample(x, p, o))(offs / BAND_STEP), RIDGE_SIGMA)
    own_r = own_r[k_o // BAND_STEP]
    own = jnp.nanmedian(jnp.where(valid, own_r, jnp.nan))
    slopes = np.linspace(-MAX_SLOPE, MAX_SLOPE, N_SLOPES)
    # Line sums by the shift theorem: r(j + slope · o) for every slope and offset is one
    # phase ramp on the FFT of the band's column o (zero-padded: no wrap-around).
    pad = n + int(math.ceil(MAX_SLOPE * BAND)) + 2
    k = np.arange(pad // 2 + 1)
    o_np = np.arange(-BAND, BAND + 1, BAND_STEP)
    ramp = np.exp(2j * np.pi * k[None, None, :] * slopes[:, None, None] * o_np[None, :, None] / pad)
    spec = jnp.fft.rfft(r, n=pad, axis=0)  # (K, O)
    ctype = spec.dtype

    def side_sum(w):
        w = w.astype(dtype) / jnp.maximum(jnp.sum(w), 1)
        line = jnp.einsum("ko,o,sok->sk", spec, w.astype(ctype), jnp.asarray(ramp, ctype))
        return jnp.fft.irfft(line, n=pad, axis=1)[:, :n]

    # both sides must carry the line
    sums = jnp.minimum(side_sum(side & (offs < 0)), side_sum(side & (offs > 0)))  # (S, N)
    slopes = jnp.asarray(slopes, dtype)
    best = jnp.argmax(sums.reshape(-1))
    si, jc = best // n, best % n
    score = sums[si, jc]
    noise = 1.4826 * jnp.nanmedian(jnp.abs(sums - jnp.nanmedian(sums)))
    found = (score > LINE_SHARE * own) & (score > LINE_NOISE * noise) & jnp.isfinite(own)
    return jc, slopes[si], found, score / jnp.where(own > 0, own, jnp.inf)


@functools.partial(jax.jit, static_argnames=("axis",))
def interpolated(mono, pos, valid, width, *, axis: int):
    """(N,) mask of the centres to interpolate: those whose profile the other stripe of a
    turned cross enters off-centre (`other_stripe`: within |slope| · (`REACH_WIDTHS` σ_t +
    `REACH_PX`) + `REACH_PAD` centres of the crossing, where |slope| ≥ `MIN_SLOPE`) and those
    within `CUT_WIDTHS` σ_t of the image's border across the stripe (a cut profile).

    Args:
        mono: (H, W) monochrome image, bright stripe.
        pos, valid: (N,) path centres along the search axis and their mask.
        width: σ_t of the smoothed profile (px, scalar: √(σ² + s²), s the stripe's std).
        axis: 0 horizontal stripe (one centre per column), 1 vertical.
    """
    jc, s, found, _ = other_stripe(mono, pos, valid, width, axis=axis)
    j = jnp.arange(pos.shape[0])
    reach = jnp.abs(s) * (REACH_WIDTHS * width + REACH_PX) + REACH_PAD
    turned = (jnp.abs(j - jc) <= reach) & found & (jnp.abs(s) >= MIN_SLOPE)
    length = mono.shape[0] if axis == 0 else mono.shape[1]
    p = jnp.nan_to_num(pos)
    d = CUT_WIDTHS * width
    cut = (p < d) | (p > length - 1 - d)
    return (turned | cut) & valid
