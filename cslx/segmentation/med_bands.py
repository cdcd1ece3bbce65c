"""MED only where the stripe is: first-pass bands, linear-phase MED there, Steger (issue 13).

The paper's method (section 3.2) runs MED on every column (row) of the frame: L = 240 / 320
taps over 480 / 640 samples, 11–13 fixed-point steps from the flat start, ≈ 100 ms for
both stripes on the 2-core CPU of results/bench_speed.md. The stripe covers a few pixels of
each segment, so this module runs it where the stripe is, for archives of frames
(`cslx extract --method med`), the same way the pipeline does on a frame without tracking
state (`cslx.runtime.pipeline`):

1. first pass: the brightest sample of every column (horizontal stripe) or row (vertical
   stripe) of the monochrome image; the band (``2·half`` samples) is centred on their median;
2. when at least ``fraction`` of those samples lie inside the band (``margin`` px away from
   its edges, except at the image border), MED runs on the band with a short filter
   (``L`` taps) restricted to linear phase (`cslx.segmentation.med.med`, ``symmetric=True``:
   the delay is exactly (L − 1)/2; free filters on short segments become one-sided and move
   centres by up to 0.18 px, see the notes of `cslx.segmentation.med`) and Steger on its
   output; centres outside the band are reported as not found; when they lie more than
   `MAX_PEAK_OFFSET` px (median) from the band's smoothed maxima, the band result
   is not used (the failure mode of `initial_filters`) and the next step runs instead;
3. otherwise (no clear stripe, two stripes far apart) the frame's segments all go through
   the paper's full-frame MED (flat start, ridge delay) and Steger.

Frames are processed by `lax.scan` (on the CPU `lax.cond` then runs only the chosen branch),
and each frame's band MED starts from the previous frame's band filter: linear-phase MED
converges to the same fixed point from the flat start and from a neighbour's filter (on dev
video frames the centres agreed within 0.001 px median) in 3–6 steps instead of 12–21.
"""

from __future__ import annotations

import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Bool, Float, Int, UInt8

from ..reductions import first_argmax
from .med import initial_filter, med
from .steger import Centres, steger_centres

__all__ = [
    "BandConfig",
    "BandResult",
    "band_centres",
    "extract_frames",
    "band_snr_scale",
    "initial_filters",
]


class BandConfig(eqx.Module):
    """Settings of band MED; every field shapes the compiled program (static).

    weights: colour weights of eq. (8) (default R − G). half_h / half_w: half-height of the
    row band of the horizontal stripe and half-width of the column band of the vertical
    stripe, px (the pipeline's ``roi_half_h`` / ``roi_half_w``). margin, fraction: the
    first-pass rule (module notes). L: band filter length (the pipeline's ``L_roi``).
    max_steps, tol: MED's cap and relative kurtosis tolerance (Table 2, step 5).
    sigma, threshold, snr: Steger's scale and thresholds (`steger_centres`).
    """

    weights: tuple[float, float, float] = eqx.field(static=True, default=(1.0, -1.0, 0.0))
    half_h: int = eqx.field(static=True, default=32)
    half_w: int = eqx.field(static=True, default=64)
    margin: int = eqx.field(static=True, default=8)
    fraction: float = eqx.field(static=True, default=0.9)
    L: int = eqx.field(static=True, default=16)
    max_steps: int = eqx.field(static=True, default=30)
    tol: float = eqx.field(static=True, default=1e-4)
    sigma: float = eqx.field(static=True, default=2.0)
    threshold: float = eqx.field(static=True, default=0.1)
    snr: float = eqx.field(static=True, default=5.0)


#: Largest median |band centre − smoothed maximum of the band| (px) accepted from band MED.
MAX_PEAK_OFFSET = 1.5


class BandResult(NamedTuple):
    """One stripe of one frame (leading frame axis from `extract_frames`).

    centres: `Centres` over the whole image (W for the horizontal stripe, H for the
    vertical one; not valid outside the band). filter: the band filter for the next frame.
    steps: MED steps. used_band: the band was used (False: full-frame MED).
    """

    centres: Centres
    filter: Float[Array, " L"]
    steps: Int[Array, ""]
    used_band: Bool[Array, ""]


def _channel_sum(rgb, weights, dtype):
    out = jnp.zeros(rgb.shape[:-1], dtype)
    for c, w in enumerate(weights):
        if w != 0:
            out = out + float(w) * rgb[..., c].astype(dtype)
    return out


def _locate(I, axis: int, half: int, cfg: BandConfig):
    """First pass: (first sample of the band, whether the stripe fits in it)."""
    size = I.shape[axis]
    peaks, _ = first_argmax(I, axis)
    centre = jnp.median(peaks.astype(I.dtype))
    start = jnp.clip(jnp.round(centre).astype(jnp.int32) - half, 0, size - 2 * half)
    lo = jnp.where(start == 0, -1, start + cfg.margin)
    hi = jnp.where(start == size - 2 * half, size, start + 2 * half - 1 - cfg.margin)
    inside = jnp.mean((peaks >= lo) & (peaks <= hi))
    return start, inside >= cfg.fraction


def _smoothed_peak(band, axis: int):
    """Brightest sample of each segment after a [1, 2, 3, 2, 1] smoothing along it."""
    taps = (1.0, 2.0, 3.0, 2.0, 1.0)
    pad = [(0, 0), (0, 0)]
    pad[axis] = (2, 2)
    x = jnp.pad(band, pad)
    n = band.shape[axis]
    s = sum(t * lax.slice_in_dim(x, k, k + n, axis=axis) for k, t in enumerate(taps))
    return first_argmax(s, axis)[0].astype(band.dtype)


def _steger(B, axis, cfg: BandConfig, snr_scale: float = 1.0) -> Centres:
    snr = cfg.snr * snr_scale
    return steger_centres(B, sigma=cfg.sigma, axis=axis, threshold=cfg.threshold, snr=snr)


def band_snr_scale(band: int, frame: int) -> float:
    """Factor on Steger's ``snr`` in a band of ``band`` of the frame's ``frame`` samples.

    ``snr`` compares a ridge point with the mean |λ| of the image it is given: over a frame
    that mean is the background's, over a band around the stripe it is mostly the stripe's.
    When the stripe carries most of Σ|λ|, the frame's mean is the band's times band/frame,
    so the band test uses snr·band/frame. With the frame's snr the bands of dev frames lost
    9–11 % of the horizontal stripe's columns that full-frame MED + Steger kept.
    """
    return band / frame


def band_centres(I: Float[Array, "h w"], W0: Float[Array, " L"], axis: int, cfg: BandConfig):
    """One stripe of one monochrome frame (module notes): `BandResult`.

    axis 0: the horizontal stripe (one centre per column); 1: the vertical stripe.
    W0: the band filter to start from (`initial_filters`, or the previous frame's).
    """
    height, width = I.shape
    half = cfg.half_h if axis == 0 else cfg.half_w
    if not 0 < 2 * half < I.shape[axis]:
        raise ValueError(f"band of {2 * half} samples does not fit a frame of {I.shape}")
    start, fits = _locate(I, axis, half, cfg)

    def in_band():
        zero = jnp.zeros((), jnp.int32)
        if axis == 0:
            band = lax.dynamic_slice(I, (start, zero), (2 * half, width))
        else:
            band = lax.dynamic_slice(I, (zero, start), (height, 2 * half))
        r = med(band, axis=axis, L=cfg.L, init=W0, tol=cfg.tol, max_steps=cfg.max_steps,
                symmetric=True, ridge_sigma=cfg.sigma)  # fmt: skip
        ok = jnp.all(jnp.isfinite(r.filter))
        scale = band_snr_scale(2 * half, I.shape[axis])
        c = _steger(jnp.where(ok, r.output, band), axis, cfg, scale)
        c = Centres(c.pos + start.astype(c.pos.dtype), c.valid, c.strength)
        rough = _smoothed_peak(band, axis) + start
        return c, jnp.where(ok, r.filter, W0), r.steps.astype(jnp.int32), rough

    def full():
        r = med(I, axis=axis, tol=cfg.tol, max_steps=cfg.max_steps, ridge_sigma=cfg.sigma)
        ok = jnp.all(jnp.isfinite(r.filter))
        c = _steger(jnp.where(ok, r.output, I), axis, cfg)
        return c, W0, r.steps.astype(jnp.int32), jnp.zeros((), bool)

    def checked():
        # A filter with two lobes copies the stripe to either side (`initial_filters`):
        # the centres then leave the input's smoothed maxima by ≈ the lobe spacing.
        c, W, steps, rough = in_band()
        off = jnp.nanmedian(jnp.where(c.valid, jnp.abs(c.pos - rough), jnp.nan))
        res = (c, W, steps, jnp.ones((), bool))
        return lax.cond(off <= MAX_PEAK_OFFSET, lambda: res, full)

    return BandResult(*lax.cond(fits, checked, full))


def initial_filters(cfg: BandConfig, dtype=jnp.float32) -> Float[Array, "2 L"]:
    """Table 2's flat start for the two band filters (horizontal, vertical stripe).

    Measured alternatives: from the centred impulse of an odd L linear-phase MED converges
    to a one-lobe sharpening filter (centre ≈ 0.9, −0.3 at ±1) that amplifies speckle: on
    dev frames the median |centre − truth| rose from 0.08–0.13 px to 0.34–0.50 px. From the
    flat start (L = 16) it converges to a filter with two lobes ≈ ±2.5 px apart, which on the
    rendered stripes (σ ≈ 2 px) acts as one smoothing lobe; on a narrow synthetic stripe it
    can copy the stripe to either side instead, which `band_centres` detects.
    """
    W = initial_filter("flat", cfg.L, dtype)
    return jnp.stack([W, W])


@functools.partial(jax.jit, static_argnames=("cfg", "stripes"))
def _extract_frames(frames, filters, cfg, stripes):
    dtype = filters.dtype

    def one(filters, rgb):
        I = _channel_sum(rgb, cfg.weights, dtype)
        out = []
        for s, axis in (("h", 0), ("v", 1)):
            if s in stripes:
                r = band_centres(I, filters[axis], axis, cfg)
                filters = filters.at[axis].set(r.filter)
                out.append(r)
        return filters, tuple(out)

    return lax.scan(one, filters, frames)


def extract_frames(
    frames: UInt8[Array, "f h w 3"],
    filters: Float[Array, "2 L"],
    cfg: BandConfig = BandConfig(),
    stripes: tuple[str, ...] = ("h", "v"),
) -> tuple[Float[Array, "2 L"], tuple[BandResult, ...]]:
    """Band MED + Steger on a batch of RGB frames, one after the other, jit-compiled.

    Args:
        frames: (F, H, W, 3) uint8 RGB frames.
        filters: (2, L) band filters to start from (horizontal, vertical stripe):
            `initial_filters` for the first batch, the returned ones for the next.
        cfg: `BandConfig` (static).
        stripes: which stripes, "h" and/or "v" (static).

    Returns:
        (the band filters after the last frame, one `BandResult` per stripe in ``stripes``
        order, each with a leading frame axis).
    """
    stripes = tuple(s for s in ("h", "v") if s in stripes)
    frames = jnp.asarray(frames)
    if frames.ndim != 4 or frames.shape[-1] != 3:
        raise ValueError(f"expected frames of shape (F, H, W, 3), got {frames.shape}")
    return _extract_frames(frames, jnp.asarray(filters), cfg, stripes)
