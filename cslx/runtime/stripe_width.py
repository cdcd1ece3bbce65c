"""The stripe's width on a frame, and Steger's σ for it (host-side, NumPy, outside the jit).

Steger (1998) needs σ ≥ w/√3 for a bar profile of half-width w; for a Gaussian profile of
std s the bar of the same second moment gives σ ≥ s (`cslx.segmentation.steger.
sigma_for_width`, the robust extractor's `cslx.segmentation.robust.stripe_sigma`). Below it
the smoothed profile of a wide stripe keeps several maxima (speckle, a clipped core's
flanks) and Steger's detector picks the wrong one. The stripe's width in pixels depends on
the rig (focal length, frame size, stand-off), the laser (sheet thickness, power: a
clipped core is a wide plateau) and the light, so the tracker (`cslx.runtime.tracker.
Tracker`) measures it: on the first frame after a start or `reset` with both stripes, the
median FWHM of the column (row) profiles (`stripe_widths`, every 4th profile; 8.5 ms
at 640×480, load 1.5–5, once per start or reset), and σ = FWHM / 2.355 (the profile's
std) on a 0.5 px grid (`choose_sigma`), at
most 6 px × min(H, W)/480 (the robust extractor's ceiling), once s exceeds the configured σ
by 1.8 px or more (`SWITCH`; 2 px at 640×480, `cslx.runtime.pipeline.PipelineConfig.sigma`);
narrower stripes keep the configured σ. One σ for both stripes: the wider one's. Each σ is
a static setting of its own compiled program, built once per tracker (0.9 s from a warm
persistent cache, ≈ 12 s cold, on the first measured frame) and kept, so nothing is
compiled per frame; a rig whose σ is known can set it in the configuration and skip that.

Rig audit (`experiments/rig_sigma.py`: T scenes, clean / sunny by seed parity, seeds
8800–8805, a cold and a tracking frame each, the tracker's pipeline; gross = centres
> 1 mm from the truth in 3-D, per stripe and frame, mean (range); median error, median
over frames (range)), before (σ 2) → after (this rule), horizontal / vertical stripe:

- default 640×480 rig: FWHM 4.4–4.8 px clean, 5.4–7.3 px sunny (clipped cores): σ 2 kept,
  identical. σ = s without `SWITCH` gave σ 3 on the sunny frames (gross 4.4 (0–14) /
  2.5 (0–6) → 1.2 (0–7) / 0.6 (0–4), median 0.115 / 0.134 → 0.102 / 0.117 mm) and σ 2.5–3.5
  in glare, shadow and sun in the tracker over the rendered T approaches of
  `experiments/tracking_sequences.py` (dev seeds 7301, 7302, 7305, 48 frames): offset error
  mean better in all 6 sunny runs (e.g. 0.257 → 0.095 mm) but worse in 5 of 6 glare runs
  (0.103 → 0.162 mm), false T reports 0 → 11 and 0 → 4 in two sunny runs, 1 → 9 in a glare
  run. Mixed, so the default rig keeps σ 2: its widest stripes (7.9 px, sequences of seed
  7305, s = 3.36 px) are below the switch (8.95 px, s = 3.8 px);
- 640×480 with a 1.6× longer lens (FWHM 6.1–11.2 px; σ 4.5–5 on the 3 sunny scenes, 2 on
  the clean ones): gross 12.4 (0–34) / 7.9 (1–20) → 1.4 (0–8) / 2.4 (0–10), median
  0.138 / 0.180 → 0.090 / 0.124 mm;
- 1280×720 at twice the focal length (floor σ 3 by the frame size; the clean scenes, FWHM
  7.1–9.0 px, keep it; the 3 sunny ones, 12.2–13.2 px, get σ 5–5.5): on those, σ 3 gross
  25.8 (12–36) / 14.3 (11–18), median 0.077 / 0.102 mm → 7.7 (0–12) / 4.8 (0–13),
  0.049 / 0.060 mm (σ 2: 55.7 / 46.2 gross);
- 320×240 at half the focal length (FWHM 2.6–4.3 px): σ 2 kept, identical (0.8 / 1.1 gross);
- thick laser (sheet 3.6 mm FWHM, stripe 14–23 px): σ 2 gives 278 (208–321) / 248
  (199–301) gross, median 1.68 / 1.60 mm; the rule without its ceiling (σ 6–10): 12.8 (0–41)
  / 15.3 (0–32), 0.128 / 0.248 mm;
- thin laser (sheet 0.25 mm, lens blur 0.4 px; FWHM 1–2 px): σ 2 kept, identical (2.7 /
  0.2 gross, 0.040 / 0.042 mm);
- green laser: the tracker's R − G space sees it dark (60.8 / 39.2 gross at any σ): a
  colour-space matter, not σ's
  (`cslx.runtime.stripe_colour` chooses the weights).

Held out (seeds 8810–8813, not used to choose the rule): default rig identical (FWHM up to
7.2 px); 1.6× lens 14.2 (0–32) / 5.8 (0–11) → 0.5 (0–2) / 0.8 (0–3), median 0.129 / 0.150
→ 0.088 / 0.109 mm; thick laser 267.5 (211–319) / 233.0 (171–286) → 28.0 (1–61) / 18.5
(6–29), 2.03 / 1.26 → 0.172 / 0.224 mm at the ceiling σ 6 (better, not solved: a 16–23 px
stripe wants σ 7–10 and a tracking band wider than 64 rows); 1280×720 at twice the focal
length, sunny seeds 8811 and 8813 (FWHM 12.6–13.6 px), frame-size σ 3 → σ 5.5–6: gross
24–36 / 9–14 → 0 / 0 per frame, median 0.072–0.081 / 0.108–0.143 → 0.040–0.055 /
0.062–0.079 mm. Figure 22's closed loop (dev
seeds 2201, 2203, 2204, every nuisance): FWHM 4.5–7.5 px, σ 2 and one program throughout.

Where one stripe is much narrower than the other (1.6× lens, seed 8805: 10.6 / 6.1 px),
the narrower one keeps some gross centres at the wider one's σ (10 per frame at σ 4.5
against 15–20 at σ 2): a σ per stripe would need a second static σ in the pipeline.
"""

from __future__ import annotations

import math

import numpy as np

from ..config import SIGMA_MAX

__all__ = [
    "check_due",
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
#: σ follows the stripe only when its profile std exceeds `floor` (the configured σ) by at
#: least this much, px: below, the tracker's evidence on the default rig was mixed (docstring).
SWITCH = 1.8
#: The check (σ and colour weights, `cslx.runtime.stripe_colour`) runs on every frame after a
#: start or `reset` until both stripes are measured, but only on the first `CHECK_FRAMES`;
#: after those on every `CHECK_EVERY`-th frame (`check_due`).
CHECK_FRAMES = 8
CHECK_EVERY = 16


def check_due(frame: int) -> bool:
    """Whether the tracker checks σ and the colour weights on its `frame`-th frame (0, 1, …
    since a start or `reset`) while no frame has measured both stripes yet.

    Each check costs ≈ 27 ms at 640×480 (the widths ≈ 8.5 ms, the colour check ≈ 18 ms), on
    top of the frame. A run whose first frames show no stripe (the plate not yet in view, a
    covered lens, black frames) would otherwise pay it on every frame; checking every 16th
    frame after the first 8 keeps the average below 2 ms per frame and still adapts the
    program (a green laser in R − G gives 40–60 gross centres per stripe) within 16 frames
    of the stripes appearing.
    """
    return frame < CHECK_FRAMES or (frame - CHECK_FRAMES) % CHECK_EVERY == CHECK_EVERY - 1


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


def choose_sigma(width_px: float, floor: float, size: int = 480) -> float:
    """Steger's σ for a stripe of FWHM `width_px`: `floor` unless its profile std s is at
    least `floor` + `SWITCH`, then s on a `STEP` grid, at most `SIGMA_MAX` × `size`/480
    (`size`: the frame's smaller side; module docstring); `floor` when the width is unknown."""
    if not math.isfinite(width_px) or width_px / FWHM_PER_STD < floor + SWITCH:
        return floor
    ceiling = SIGMA_MAX * max(1.0, size / 480)
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
