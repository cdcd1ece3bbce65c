"""The stripe's width on a frame, and Steger's σ for it (host-side, NumPy, outside the jit).

Filled in below (`choose_sigma`).
"""

from __future__ import annotations

import math

import numpy as np

__all__ = [
    "choose_sigma",
    "frame_sigma",
    "profile_widths",
    "stripe_width",
    "stripe_widths",
    "with_frame_sigma",
]

#: Sensor maximum: a pixel with a channel at this value holds a lower bound, not a value.
CLIP = 255
#: Gaussian FWHM per standard deviation, 2 √(2 ln 2).
FWHM_PER_STD = 2.0 * math.sqrt(2.0 * math.log(2.0))
#: σ grid (px): one compiled program per σ, so few distinct values.
STEP = 0.5
#: Largest σ, px (`cslx.segmentation.robust.SIGMA_MAX`'s value).
SIGMA_MAX = 6.0


def profile_widths(
    rgb: np.ndarray, weights, axis: int, stride: int = 4, min_contrast: float = 12.0
) -> np.ndarray:
    """Full width at half maximum (px) of the stripe's profile in every `stride`-th column
    (``axis`` 0, the horizontal stripe) or row (``axis`` 1, the vertical stripe).

    The monochrome image is eq. (8)'s weighted sum; clipped pixels (a channel at 255) count
    as the profile's peak (a saturated core is as wide as its plateau at least). Per profile:
    peak p (the largest unclipped value), background b (its median), the run of samples
    ≥ (p + b)/2 around the peak, its two ends interpolated linearly. NaN where p − b is below
    `min_contrast` (no stripe) or the run reaches the frame's edge.
    """
    rgb = np.asarray(rgb)
    x = rgb[:, ::stride] if axis == 0 else rgb[::stride].transpose(1, 0, 2)
    m = x.astype(np.float32) @ np.asarray(weights, np.float32)  # (n along the profile, k)
    clipped = np.any(x >= CLIP, axis=-1)
    peak = np.max(np.where(clipped, -np.inf, m), axis=0)
    m = np.where(clipped, peak[None], m)
    base = np.median(m, axis=0)
    half = 0.5 * (peak + base)
    above = m >= half[None]
    n = m.shape[0]
    idx = np.arange(n)[:, None]
    top = np.argmax(m, axis=0)
    below_lo = ~above & (idx < top[None])
    below_hi = ~above & (idx > top[None])
    lo = np.where(below_lo.any(0), n - 1 - np.argmax(below_lo[::-1], axis=0), -1)
    hi = np.where(below_hi.any(0), np.argmax(below_hi, axis=0), n)
    with np.errstate(invalid="ignore"):  # a wholly clipped profile has no peak (−inf)
        ok = (lo >= 0) & (hi < n) & (peak - base >= min_contrast)
    cols = np.arange(m.shape[1])
    lo_c, hi_c = np.clip(lo, 0, n - 2), np.clip(hi, 1, n - 1)

    def crossing(i, j):  # where the profile passes `half` between samples i and j
        a, b = m[i, cols], m[j, cols]
        return i + (half - a) / np.where(b != a, b - a, 1.0) * (j - i)

    with np.errstate(invalid="ignore", divide="ignore"):
        width = crossing(hi_c, hi_c - 1) - crossing(lo_c, lo_c + 1)
    return np.where(ok, width, np.nan)


def stripe_width(rgb: np.ndarray, weights, axis: int, stride: int = 4) -> float:
    """Median FWHM (px) of the stripe's profiles (`profile_widths`); NaN when fewer than a
    quarter of the profiles are measured (no stripe on this frame)."""
    w = profile_widths(rgb, weights, axis, stride)
    ok = np.isfinite(w)
    return float(np.median(w[ok])) if ok.mean() >= 0.25 else math.nan


def stripe_widths(rgb: np.ndarray, weights, stride: int = 4) -> tuple[float, float]:
    """(horizontal, vertical) stripe's median FWHM, px (`stripe_width`)."""
    return stripe_width(rgb, weights, 0, stride), stripe_width(rgb, weights, 1, stride)


def choose_sigma(width_px: float, floor: float, ceiling: float = SIGMA_MAX) -> float:
    """Steger's σ for a stripe of FWHM `width_px`: its profile std, on a `STEP` grid, within
    [`floor`, `ceiling`] (module docstring); `floor` when the width is unknown."""
    if not math.isfinite(width_px):
        return floor
    return float(min(max(floor, round(width_px / FWHM_PER_STD / STEP) * STEP), ceiling))


def frame_sigma(config, height: int, width: int) -> float:
    """The σ `cslx.runtime.pipeline.process_frame` uses for `config` on an (height, width)
    frame (``config.sigma``, scaled above 480 px)."""
    from .pipeline import _frame_config

    return float(_frame_config(config, height, width).sigma)


def with_frame_sigma(config, sigma: float, height: int, width: int):
    """`config` whose σ on an (height, width) frame is `sigma` (`frame_sigma`); `config`
    itself when it already is."""
    import dataclasses

    current = frame_sigma(config, height, width)
    if sigma == current:
        return config
    return dataclasses.replace(config, sigma=config.sigma * sigma / current)
