"""The whole per-frame pipeline in one compiled function: RGB frame → stripes → 3-D → weld.

One frame (docs/architecture.md):

1. colour space, eq. (8): I = w_r R + w_g G + w_b B (static weights, R − G by default);
2. MED, eqs. (18)–(24): one FIR filter down the columns (horizontal stripe) and one along
   the rows (vertical stripe), each warm-started from the previous frame's filter held in
   `PipelineState` (docs/corrections.md, 5), delay-compensated (correction 6);
3. Steger's detector on each MED output: one sub-pixel centre per column / per row;
4. triangulation (correction 3 of eq. (27)) on plane 0 / plane 1 into the robot frame;
5. weld features (`cslx.runtime.weld.weld_features`): the followed bead on the horizontal stripe,
   a crossing bead (T-junction) on the vertical stripe.

Tracking mode (region of interest). In video the stripes barely move between frames, so
after a frame where both stripes were found the next frame processes only a band of
``2·roi_half_h`` rows around the horizontal stripe (all columns) and a band of
``2·roi_half_w`` columns around the vertical stripe (all rows). The band sizes are static,
their offsets dynamic (`lax.dynamic_slice`), so one compiled program serves every frame;
`lax.cond` picks the band branch or the full-frame branch (on the CPU only the chosen branch
runs). The MED filters of the bands are shorter (``L_roi``, a band is a short segment) and
kept apart from the full-frame filters. A stripe that leaves its band, or too few centres,
switches the next frame back to a frame without tracking state. Such a frame (the first one
too) takes its bands from a cheap first pass (the brightest sample of every column / row,
`_first_pass`) and runs MED from the band filters to convergence there; only when the
stripes do not fit the bands does it run MED on the full frame. Centres outside the band are
reported as not found; inside it they agree with full-frame processing
(tests/runtime/test_pipeline.py). The bands are cut out of the uint8 RGB frame before the
colour sum and the clipped-core fill (``band_first``, `cslx.runtime.band_input`; the same
values as the bands of the converted frame), so a tracking frame never converts the whole
frame.

Everything is pure JAX on one frame and jit-compiled at `process_frame`;
`cslx.runtime.batch.process_batch` runs it over a stack of frames (under vmap `lax.cond`
evaluates both branches: archives should use the full frame, ``roi=False``).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Bool, Float, Int, UInt8

from ..segmentation.med import default_filter_length, initial_filter, med, med_apply
from ..segmentation.med_bands import band_snr_scale, first_peak
from ..segmentation.steger import Centres, steger_centres
from ..sensor import Sensor, triangulate
from .band_input import band_image, colour_sum, frame_input, frame_stats, image_cutter, rgb_cutter
from .small_ops import masked_median, window_nanmedian
from .weld import WeldConfig, WeldFeature, weld_features

__all__ = [
    "FrameResult",
    "PipelineConfig",
    "PipelineState",
    "frame_summary",
    "init_state",
    "process_frame",
    "SUMMARY_FIELDS",
    "stripe_points",
    "clean_profile",
    "colour_sum",
]


class PipelineConfig(eqx.Module):
    """Settings of the per-frame pipeline; every field shapes the compiled program (static).

    weights: colour weights (w_r, w_g, w_b) of eq. (8); default R − G (the paper's space).
    L_h / L_v: full-frame MED filter lengths for the horizontal (down columns) and vertical
        (along rows) stripe; None = 50 % of the segment (the paper's choice, correction 7).
    L_roi: MED filter length inside the tracking bands (≤ the band size). 16, even; the odd
        lengths 15 and 17, whose whole-sample delay (L − 1)/2 lets `med` read the band output
        as a slice of the convolution (`cslx.segmentation.med_fft.centre_output`), were tried
        and dropped (issue 13). 17: on dev video (seeds 0 / 1 / 3) band − full-frame centres
        0.023 / 0.010 / 0.014 px (16: 0.025 / 0.010 / 0.014), but on the clean rendered cross
        frame of tests/runtime/test_pipeline.py its band filter converged to two lobes 6 px
        apart and the horizontal stripe came out 3.0 px off (16: 0.11 px). 15: no lobes and
        band − full-frame agreement as good (worst |median| over 6 frames × 2 stripes of
        rendered video, clean / sunny / glare / shadow × dev seeds 0, 1, 3: ≤ 0.019 px, 16:
        ≤ 0.019 px; clean cross and straight frames of the tests' scenes, seeds 31–36:
        ≤ 0.013 px, 16: ≤ 0.012 px) and tracking ``process_frame`` 6 % faster (10.28 against
        10.93 ms median, 150 interleaved frames each, load 3.2–3.4), but the centres are
        noisier: median |centre − truth| 0.132 against 0.126 px (worse in 11 of the 12
        videos), 0.142 against 0.119 px on the horizontal stripe of the clean frames (12 of
        12), and over the rendered T approaches of experiments/tracking_sequences.py (dev
        seed 7301, tracker with MED; its default has none) offset error mean up in 7 of 8
        runs (shadow, beside: 0.148 → 0.237 mm, max 0.467 → 0.713 mm).
    max_steps / tol: MED fixed-point cap and relative kurtosis tolerance (Table 2, step 5),
        for the full frame; roi_max_steps for the tracking bands: the band filter is carried
        from frame to frame and evolves slowly, so a fixed 2 steps per frame keep it at the
        fixed point (issue 13; tracking over rendered sunny video, band − full-frame MED
        centres, worst |median| over 7 frames × 2 stripes: dev seed 1 0.010 px with 1, 2, 3
        steps, 0.009 px with ≤ 6 (5 taken); held-out seed 2 0.029 px with 1 and 2; median
        |centre − truth| unchanged, 0.104–0.110 px). 2 rather than 1 for margin after a
        sudden change; ≤ 6 cost ≈ 2 ms more a frame. ``tol`` is 1e-2, not Table 2's 1e-4
        (issue 13, `experiments.med_start`, dev seeds 7100–7113, 2 frames of each red-laser
        condition, cold frames from `init_state`): the kurtosis of the last steps creeps
        by < 1 % a step while no centre moves. With the first-pass bands (79 % of those
        frames) MED took 15.7 / 16.8 steps (h / v) at 1e-4 and 10.1 / 10.3 at 1e-2, the
        frame 38.8 → 30.0 ms (load 6); median / p95 error per condition within
        ±0.002 / ±0.015 mm. On the full frame (``roi=False``) 15.8 / 13.9 → 9.2 / 9.4
        steps, 178 → 121 ms at load 5, every condition within ±0.01 / ±0.22 mm (p95 of the
        saturated stripe v 5.07 → 4.85 mm).
    start: the full-frame filters' cold start (`init_state`): ``"impulse"`` (a centred unit
        impulse: the first output is the input itself) or Table 2's ``"flat"`` 1/√L. From
        the flat start the first 3–4 steps only climb out of a low-pass filter (excess
        kurtosis ≈ −1 → 1 → 16–55) before the stripe sharpens. Same runs, full frame, tol
        1e-2: flat → impulse 9.2 / 9.4 → 5.9 / 5.7 steps, 121 → 83 ms; the saturated core
        found where the flat start's fixed point missed it (v: p95 4.85 → 0.45 mm, gross
        5.6 → 2.0 % over all conditions), the others within ±0.02 mm median, p95 ±0.05 mm
        (printed h 1.14 → 1.19 mm). The band filters always start flat: started from the
        impulse the 16-tap linear-phase band filters converged elsewhere (saturated h
        median 0.08 → 29 mm, clean 0.119 → 0.148 mm).
    med_stride: on the full frame, MED's filter is found on every k-th column (row) and
        then applied to all of them (`cslx.segmentation.med.med_apply`): one filter serves
        the whole frame, and 320 / 240 segments pin it down as well as 640 / 480 (issue 13,
        `experiments.med_start --pipeline --full-frame`, dev seeds 7100–7113, 2 frames of
        each red-laser condition: k = 2 / 3 against 1, every condition within ±0.007 mm
        median and ±0.025 mm p95, cold full frame 70.4 → 60.0 / 56.2 ms at load 4). 2 is the
        default; the bands (64 / 128 samples a segment) use every segment.
    sigma: Steger scale, px, for frames up to 480 px; larger frames scale it by
        min(H, W) / 480 (`_frame_config`). Rig audit, 1280×720 at twice the focal length
        (clean T scenes, dev seeds 8804–8805, cold frames): σ 2 gave 36–91 gross (> 1 mm)
        centres per stripe, median 0.32–0.39 mm; σ 3 (this rule) 0–5, 0.15–0.21 mm; σ 4
        0, 0.09–0.14 mm (the frame size understates that rig's 2× magnification; the
        focal length, a traced value here, cannot set a static σ).
    threshold / snr: Steger's relative and noise-floor thresholds.
    roi_half_h / roi_half_w: half-height of the row band around the horizontal stripe and
        half-width of the column band around the vertical stripe, px; 0 disables the ROI.
    roi_margin: a stripe closer than this to its band's edge ends tracking mode.
    first_pass / first_pass_fraction: on a frame without tracking state (the first, or
        after the stripes were lost) with the ROI allowed, locate the bands from the
        brightest sample of each column / row (`_first_pass`) and run MED (from the band
        filters in the state, up to ``max_steps``) and Steger in the bands when at least
        ``first_pass_fraction`` of those samples fall inside them; otherwise, or with
        ``roi=False``, the full frame. MED only where the stripe is (issue 13).
    min_valid_fraction: share of columns (rows) with a centre needed to keep tracking mode.
    median_half / outlier_mm / smooth_half: 3-D profile clean-up before the weld features
        (`clean_profile`: gross outliers out, light smoothing along the stripe).
    use_med: False skips MED (Steger on the monochrome image), for ablations.
    roi_med: run MED inside the tracking bands too (default on). Band MED used to be off:
        on bands of 64–192 samples its filter shifted centres by 1.0–1.9 px. The cause was
        the delay estimate, not the short segments: on short segments MED converges to a
        one-sided, edge-enhancing filter, and the cross-correlation peak (exact only for a
        symmetric filter) sits 1–2 px from where the detector sees the filtered ridge. With
        ``med_delay="ridge"`` the delay is the measured displacement of the ridge itself
        (`cslx.segmentation.med_fft.ridge_delay`): band centres then agree with full-frame
        MED to a median 0.00–0.04 px on held-out rendered frames (issue 13).
    roi_symmetric: the band filters are linear-phase (`cslx.segmentation.med.med`,
        ``symmetric=True``; delay exactly (L_roi − 1)/2). Converged free band filters are
        one-sided and moved band centres up to 0.18 px from full-frame MED (the first-pass
        bands of issue 13; also tracking, once the warm-started band filters converge over
        frames); linear-phase ones stay within 0.04 px and converge in fewer steps.
    med_delay: ``"ridge"`` (default; the ridge displacement at Steger's scale ``sigma``) or
        ``"xcorr"`` (the correlation peak of `cslx.segmentation.med.med`'s default), for the
        full frame and the bands alike. On held-out rendered frames "xcorr" left full-frame
        centres 0.05–0.15 px off the ground truth where "ridge" and Steger on the colour
        image stay within 0.05 px.
    clip_dome / clip_dome_axes / clip_dome_min_run / clip_dome_white / clip_dome_colour /
        clip_dome_along: the domed clipped-core fill (issue 12; opt-in, 0 = the flat fill).
        A clipped run longer than ``clip_dome_min_run`` px (`DOME_MIN_RUN`, √3·σ, when 0)
        along the fill axes in ``clip_dome_axes`` (1: down the columns, the horizontal
        stripe's image; 2: along the rows; 3: both) gets a parabola over the flat level,
        1 + ``clip_dome`` at its middle, unless more than ``clip_dome_white`` of its pixels
        are odd: clipped in a channel that is not the laser's (`white_mask`, when
        ``clip_dome_colour``) or, with ``clip_dome_along`` > 0, without a clipped pixel that
        many px to either side across the fill axis (a compact blob, not a core elongated
        along the stripe). Off here (the paper's pipeline); the tracker's pipeline
        (`cslx.runtime.tracker.tracking_config`) uses 1 / axes 1 / min run 7 / white 0.5,
        which over the 48 dev T approaches took the runs missing an issue-12 goal from 32
        to 15. Every setting tried helped sun and shadow but made glare worse (experiments/
        tracking_diagnostics.py's docstring; e.g. 1 / axes 1 / min run 7 / white 0.5: sunny
        offset mean 0.218 → 0.125 mm, max worst 3.09 → 1.51 mm, heading 0.520 → 0.328°;
        glare 0.101 → 0.116 mm, max worst 1.10 → 1.50 mm, heading 0.301 → 0.346°). On the
        tracker's first pass (every ``first_pass_stride``-th column) ``clip_dome_along``
        counts strided columns.
    band_first: with the ROI allowed, cut the bands out of the uint8 RGB frame first and
        convert only them (`cslx.runtime.band_input.band_image`: colour sum, clipped mask,
        `fill_clipped`; equal to the bands of the converted frame). False converts the
        whole frame first (before; tracking frames 53.8 ms against 35.8 ms in one run of
        experiments/bench_speed.py at load 5–6). first_pass_stride: with ``band_first``, the
        first pass looks at every k-th column (row) only; its band is the median of those
        peaks. stats_stride: brightness and saturated share from every k-th row and column
        (`cslx.runtime.band_input.frame_stats`; 1 = the whole frame).
    weld: the bead detector's settings. The junction threshold is lowered to 0.1 (the
        detector's default is 0.3): on rendered T frames the crossing bead on the vertical
        stripe is found at the right x_r (±0.5 mm) with confidence 0.15–0.25, and no
        straight frame gave a vertical bead at all; the tracker confirms a junction over
        two frames before reporting it.
    """

    weights: tuple[float, float, float] = eqx.field(static=True, default=(1.0, -1.0, 0.0))
    L_h: int | None = eqx.field(static=True, default=None)
    L_v: int | None = eqx.field(static=True, default=None)
    L_roi: int = eqx.field(static=True, default=16)
    max_steps: int = eqx.field(static=True, default=30)
    roi_max_steps: int = eqx.field(static=True, default=2)
    tol: float = eqx.field(static=True, default=1e-2)
    sigma: float = eqx.field(static=True, default=2.0)
    threshold: float = eqx.field(static=True, default=0.1)
    snr: float = eqx.field(static=True, default=5.0)
    roi_half_h: int = eqx.field(static=True, default=32)
    roi_half_w: int = eqx.field(static=True, default=64)
    roi_margin: int = eqx.field(static=True, default=8)
    first_pass: bool = eqx.field(static=True, default=True)
    first_pass_fraction: float = eqx.field(static=True, default=0.9)
    min_valid_fraction: float = eqx.field(static=True, default=0.5)
    median_half: int = eqx.field(static=True, default=4)
    outlier_mm: float = eqx.field(static=True, default=1.0)
    smooth_half: int = eqx.field(static=True, default=3)
    use_med: bool = eqx.field(static=True, default=True)
    start: str = eqx.field(static=True, default="impulse")
    med_stride: int = eqx.field(static=True, default=2)
    roi_med: bool = eqx.field(static=True, default=True)
    roi_symmetric: bool = eqx.field(static=True, default=True)
    med_delay: str = eqx.field(static=True, default="ridge")
    fill_clipped: bool = eqx.field(static=True, default=True)
    clip_dome: float = eqx.field(static=True, default=0.0)
    clip_dome_white: float = eqx.field(static=True, default=0.0)
    clip_dome_axes: int = eqx.field(static=True, default=3)
    clip_dome_min_run: int = eqx.field(static=True, default=0)
    clip_dome_colour: int = eqx.field(static=True, default=1)
    clip_dome_along: int = eqx.field(static=True, default=0)
    band_first: bool = eqx.field(static=True, default=True)
    first_pass_stride: int = eqx.field(static=True, default=4)
    stats_stride: int = eqx.field(static=True, default=4)
    weld: WeldConfig = WeldConfig(junction_min_confidence=0.1)

    def lengths(self, height: int, width: int) -> tuple[int, int]:
        """Full-frame filter lengths (L_h, L_v) for an (height, width) frame."""
        L_h = default_filter_length(height) if self.L_h is None else self.L_h
        L_v = default_filter_length(width) if self.L_v is None else self.L_v
        return L_h, L_v

    def roi_enabled(self, height: int, width: int) -> bool:
        return 0 < 2 * self.roi_half_h < height and 0 < 2 * self.roi_half_w < width


class PipelineState(eqx.Module):
    """What one frame hands to the next: MED filters (warm start) and the tracking bands.

    filter_h / filter_v: full-frame filters (L_h,), (L_v,); roi_filter_h / roi_filter_v:
    band filters (L_roi,). row0: first row of the horizontal stripe's band; col0: first
    column of the vertical stripe's band; tracking: process the bands (True) or the full
    frame (False) next.
    """

    filter_h: Float[Array, " Lh"]
    filter_v: Float[Array, " Lv"]
    roi_filter_h: Float[Array, " Lr"]
    roi_filter_v: Float[Array, " Lr"]
    row0: Int[Array, ""]
    col0: Int[Array, ""]
    tracking: Bool[Array, ""]


class FrameResult(NamedTuple):
    """Everything the pipeline found in one frame (leading batch axis under vmap).

    centres_h: per-column centres of the horizontal stripe (W,); centres_v: per-row centres
    of the vertical stripe (H,) (OpenCV pixels; NaN where not valid). points_h (W, 3),
    points_v (H, 3): robot-frame points, mm, after `clean_profile` (outliers dropped,
    lightly smoothed; NaN where not valid or dropped). feature_h / feature_v:
    the beads (`cslx.runtime.weld.WeldFeature`); junction: the T-junction flag. med_steps: (2,)
    fixed-point steps (h, v); kurtosis: (2,) excess kurtosis of the MED outputs. used_roi:
    only the bands were processed (tracking mode, or the bands of the first pass on a frame
    without tracking state). brightness: mean grey level of the frame
    (0..255); saturated: fraction of pixels with a channel at 255.
    """

    centres_h: Centres
    centres_v: Centres
    points_h: Float[Array, "w 3"]
    points_v: Float[Array, "h 3"]
    feature_h: WeldFeature
    feature_v: WeldFeature
    junction: Bool[Array, ""]
    med_steps: Int[Array, " 2"]
    kurtosis: Float[Array, " 2"]
    used_roi: Bool[Array, ""]
    brightness: Float[Array, ""]
    saturated: Float[Array, ""]


def init_state(
    config: PipelineConfig, image_size: tuple[int, int], dtype=jnp.float32
) -> PipelineState:
    """Cold state: full-frame filters from ``config.start``, flat band filters (W = 1/√L,
    Table 2), and full-frame processing (or the first pass's bands) first.

    Args:
        config: the pipeline settings.
        image_size: (W, H) in pixels, as `Camera.image_size`.
        dtype: float dtype of the filters (float32 is the speed path).
    """
    width, height = image_size
    L_h, L_v = config.lengths(height, width)
    return PipelineState(
        filter_h=initial_filter(config.start, L_h, dtype),
        filter_v=initial_filter(config.start, L_v, dtype),
        roi_filter_h=initial_filter("flat", config.L_roi, dtype),
        roi_filter_v=initial_filter("flat", config.L_roi, dtype),
        row0=jnp.zeros((), jnp.int32),
        col0=jnp.zeros((), jnp.int32),
        tracking=jnp.zeros((), bool),
    )


def _stripe(
    I, W0, axis, L, config: PipelineConfig, max_steps, use_med, symmetric=False, size=0, stride=1
):
    """MED (warm start W0) then Steger on one image or band: (centres, filter, steps, kurtosis).

    ``stride`` > 1: the filter is found on every stride-th segment and applied to all.
    """
    if use_med:
        sub = I if stride == 1 else (I[:, ::stride] if axis == 0 else I[::stride])
        r = med(
            sub,
            axis=axis,
            L=L,
            init=W0,
            tol=config.tol,
            max_steps=max_steps,
            delay="centre" if symmetric else config.med_delay,
            ridge_sigma=config.sigma,
            symmetric=symmetric,
        )
        ok = jnp.all(jnp.isfinite(r.filter)) & jnp.isfinite(r.kurtosis)
        # A black or clipped frame has no variance: keep the old filter, never a NaN one.
        W = jnp.where(ok, r.filter, W0)

        def out():
            if stride == 1:
                return r.output
            kind = "centre" if symmetric else config.med_delay
            return med_apply(I, r.filter, axis=axis, delay=kind, ridge_sigma=config.sigma)[0]

        B = lax.cond(ok, out, lambda: I)  # not a select (band_input's notes)
        steps, kurt = r.steps.astype(jnp.int32), jnp.where(ok, r.kurtosis, jnp.nan)
    else:
        W, B, steps, kurt = W0, I, jnp.zeros((), jnp.int32), jnp.asarray(jnp.nan, I.dtype)
    # In a band, Steger's noise floor is scaled to the frame's (`band_snr_scale`).
    snr = config.snr * (band_snr_scale(I.shape[axis], size) if size else 1.0)
    c = steger_centres(B, sigma=config.sigma, axis=axis, threshold=config.threshold, snr=snr)
    return c, W, steps, kurt


def _shift(c: Centres, offset) -> Centres:
    return Centres(c.pos + offset.astype(c.pos.dtype), c.valid, c.strength)


def _full(I, state: PipelineState, config: PipelineConfig):
    I_h, I_v = I if isinstance(I, tuple) else (I, I)
    height, width = I_h.shape
    L_h, L_v = config.lengths(height, width)
    steps = config.max_steps
    k = config.med_stride
    ch, Wh, sh, kh = _stripe(I_h, state.filter_h, 0, L_h, config, steps, config.use_med, stride=k)
    cv, Wv, sv, kv = _stripe(I_v, state.filter_v, 1, L_v, config, steps, config.use_med, stride=k)
    new = eqx.tree_at(lambda s: (s.filter_h, s.filter_v), state, (Wh, Wv))
    return ch, cv, jnp.stack([sh, sv]), jnp.stack([kh, kv]), new, jnp.zeros((), bool)


def _bands(cut, shape, state: PipelineState, config: PipelineConfig, max_steps=None):
    max_steps = config.roi_max_steps if max_steps is None else max_steps
    height, width = shape
    band_h = cut(0, state.row0, 2 * config.roi_half_h)
    band_v = cut(1, state.col0, 2 * config.roi_half_w)
    med_on, sym = config.use_med and config.roi_med, config.roi_symmetric
    L = config.L_roi
    ch, Wh, sh, kh = _stripe(
        band_h, state.roi_filter_h, 0, L, config, max_steps, med_on, sym, height
    )
    cv, Wv, sv, kv = _stripe(
        band_v, state.roi_filter_v, 1, L, config, max_steps, med_on, sym, width
    )
    new = eqx.tree_at(lambda s: (s.roi_filter_h, s.roi_filter_v), state, (Wh, Wv))
    return (
        _shift(ch, state.row0),
        _shift(cv, state.col0),
        jnp.stack([sh, sv]),
        jnp.stack([kh, kv]),
        new,
        jnp.ones((), bool),
    )


def _first_pass(peaks_h, peaks_v, shape, state: PipelineState, config: PipelineConfig):
    """Bands from a cheap first pass on a frame without tracking state: (state, fits).

    The brightest sample of every column (row) of the monochrome image (``peaks_h`` /
    ``peaks_v``, possibly of every k-th one) is a rough stripe position; the bands are
    centred on their medians. They are used when nearly all of those positions fall inside
    (the `_next_bands` rule: 98 %, away from the band edges); stray maxima (the other
    stripe, a glint) are the few columns left out. Otherwise the frame goes through
    full-frame MED.
    """
    height, width = shape
    hh, hw, m = config.roi_half_h, config.roi_half_w, config.roi_margin

    def band(peaks, half, size):
        centre = jnp.median(peaks.astype(jnp.float32))
        start = jnp.clip(jnp.round(centre).astype(jnp.int32) - half, 0, size - 2 * half)
        lo = jnp.where(start == 0, -1, start + m)
        hi = jnp.where(start == size - 2 * half, size, start + 2 * half - 1 - m)
        inside = jnp.mean((peaks >= lo) & (peaks <= hi))
        return start, inside >= config.first_pass_fraction

    row0, ok_h = band(peaks_h, hh, height)
    col0, ok_v = band(peaks_v, hw, width)
    new = eqx.tree_at(lambda s: (s.row0, s.col0), state, (row0, col0))
    return new, ok_h & ok_v


def _cold(I, state: PipelineState, config: PipelineConfig):
    """A frame without tracking: the bands of `_first_pass` if the stripes fit, else full."""
    if not config.first_pass:
        return _full(I, state, config)
    I0 = I[0] if isinstance(I, tuple) else I
    banded, fits = _first_pass(first_peak(I0, 0), first_peak(I0, 1), I0.shape, state, config)
    return lax.cond(
        fits,
        lambda: _bands(image_cutter(I), I0.shape, banded, config, config.max_steps),
        lambda: _full(I, state, config),
    )


def _cold_rgb(rgb, state: PipelineState, config: PipelineConfig, dtype):
    """`_cold` with ``band_first``: the first pass on every k-th column (row), each filled
    along its own search axis; the whole frame is converted only when the bands fail."""
    shape = rgb.shape[:2]
    k, w, fill = config.first_pass_stride, config.weights, config.fill_clipped
    dome = _dome(config)
    full = lambda: _full(frame_input(rgb, w, dtype, fill, dome), state, config)  # noqa: E731
    if not config.first_pass:
        return full()
    zero = jnp.zeros((), jnp.int32)
    cols = band_image(rgb[:, ::k], zero, shape[0], 0, w, dtype, fill, dome)
    rows = band_image(rgb[::k], zero, shape[1], 1, w, dtype, fill, dome)
    banded, fits = _first_pass(first_peak(cols, 0), first_peak(rows, 1), shape, state, config)
    cut = rgb_cutter(rgb, config.weights, dtype, config.fill_clipped, dome)
    return lax.cond(fits, lambda: _bands(cut, shape, banded, config, config.max_steps), full)


def _next_bands(ch: Centres, cv: Centres, state, config: PipelineConfig, shape):
    """Centre the bands on this frame's stripes; track only when both fit inside them.

    The band centre is the median of the valid centres, as `masked_median` (bisection on the
    float keys, equal to `jnp.nanmedian` bit for bit): the two sorts of 640 and 480 values
    cost 0.34 ms of a tracking frame (issue 13; load 6–7).
    """
    height, width = shape
    hh, hw, m = config.roi_half_h, config.roi_half_w, config.roi_margin

    def band(c: Centres, half, size, n):
        centre = masked_median(c.pos, c.valid)
        start = jnp.clip(jnp.round(centre).astype(jnp.int32) - half, 0, size - 2 * half)
        # Nearly all centres must lie inside the new band, away from its edges (a stripe
        # at the image border may touch the band's edge there); stray false centres may not.
        lo = jnp.where(start == 0, -jnp.inf, start + m)
        hi = jnp.where(start == size - 2 * half, jnp.inf, start + 2 * half - 1 - m)
        inside = jnp.sum(c.valid & (c.pos >= lo) & (c.pos <= hi))
        n_valid = jnp.sum(c.valid)
        fits = inside >= 0.98 * n_valid
        enough = n_valid >= config.min_valid_fraction * n
        return start, fits & enough & jnp.isfinite(centre)

    row0, ok_h = band(ch, hh, height, width)
    col0, ok_v = band(cv, hw, width, height)
    tracking = ok_h & ok_v
    return eqx.tree_at(
        lambda s: (s.row0, s.col0, s.tracking),
        state,
        (jnp.where(ok_h, row0, state.row0), jnp.where(ok_v, col0, state.col0), tracking),
    )


def stripe_points(sensor: Sensor, c: Centres, axis: int, plane: int, dtype):
    """Triangulate valid centres into the robot frame; NaN rows where not valid."""
    n = c.pos.shape[0]
    index = jnp.arange(n, dtype=dtype)
    # Invalid centres get a harmless pixel so the undistortion fixed point converges fast.
    pos = jnp.where(c.valid, c.pos, 0.5 * n).astype(dtype)
    uv = jnp.stack([index, pos] if axis == 0 else [pos, index], axis=-1)
    X = triangulate(sensor, uv, plane, robot_frame=True)
    return jnp.where(c.valid[:, None], X, jnp.nan)


def _windows(x: Array, k: int, fill) -> Array:
    """(N, 2k+1) stack of x shifted by −k..k along the first axis (``fill`` past the ends)."""
    pad = [(k, k)] + [(0, 0)] * (x.ndim - 1)
    xp = jnp.pad(x, pad, constant_values=fill)
    n = x.shape[0]
    return jnp.stack([lax.slice_in_dim(xp, j, j + n) for j in range(2 * k + 1)], axis=1)


def clean_profile(P: Float[Array, "n 3"], valid: Bool[Array, " n"], config: PipelineConfig):
    """Drop gross 3-D outliers and lightly smooth a stripe profile before the weld features.

    A centre picked on the wrong ridge (where the stripes cross, a glint) triangulates tens
    or hundreds of mm off the wall and splits the bead's run of high points; a point is
    dropped when its z_r is more than ``outlier_mm`` from the median z_r of its
    2·``median_half``+1 neighbours. The rest is averaged over 2·``smooth_half``+1 valid
    neighbours (≈ 1–2 mm of wall, 10× narrower than a bead; the points stay on the laser
    plane), which lowers the speckle noise of the profile by ≈ √(2·smooth_half+1).
    """
    z = jnp.where(valid, P[:, 2], jnp.nan)
    med = window_nanmedian(z, config.median_half)  # = nanmedian of the windows, no sort
    keep = valid & (jnp.abs(z - med) <= config.outlier_mm)
    if config.smooth_half > 0:
        w = _windows(keep.astype(P.dtype), config.smooth_half, 0.0)
        X = _windows(jnp.where(keep[:, None], P, 0.0), config.smooth_half, 0.0)
        count = jnp.sum(w, axis=1)
        P = jnp.sum(X, axis=1) / jnp.maximum(count, 1.0)[:, None]
    return jnp.where(keep[:, None], P, jnp.nan), keep


def _frame_config(config: PipelineConfig, height: int, width: int) -> PipelineConfig:
    """`config` with Steger's σ scaled by min(H, W) / 480 above 480 px (see `sigma`)."""
    factor = min(height, width) / 480
    return dataclasses.replace(config, sigma=config.sigma * factor) if factor > 1 else config


def _dome(config: PipelineConfig) -> tuple:
    """The clipped-core fill's dome (`cslx.runtime.band_input._fill`): () for the flat fill."""
    d, axes = config.clip_dome, config.clip_dome_axes
    if d <= 0:
        return ()
    heights = (d if axes & 1 else 0.0, d if axes & 2 else 0.0)
    return (
        *heights,
        config.clip_dome_white,
        config.clip_dome_min_run,
        config.clip_dome_colour,
        config.clip_dome_along,
    )


def _process(sensor, config: PipelineConfig, rgb, state: PipelineState, roi: bool):
    height, width = rgb.shape[:2]
    config = _frame_config(config, height, width)
    dtype = state.filter_h.dtype
    dome = _dome(config)
    if roi and config.roi_enabled(height, width) and config.band_first:
        cut = rgb_cutter(rgb, config.weights, dtype, config.fill_clipped, dome)
        ch, cv, steps, kurt, new, used_roi = lax.cond(
            state.tracking,
            lambda: _bands(cut, (height, width), state, config),
            lambda: _cold_rgb(rgb, state, config, dtype),
        )
    elif roi and config.roi_enabled(height, width):
        I = frame_input(rgb, config.weights, dtype, config.fill_clipped, dome)
        ch, cv, steps, kurt, new, used_roi = lax.cond(
            state.tracking,
            lambda: _bands(image_cutter(I), (height, width), state, config),
            lambda: _cold(I, state, config),
        )
    else:
        I = frame_input(rgb, config.weights, dtype, config.fill_clipped, dome)
        ch, cv, steps, kurt, new, used_roi = _full(I, state, config)
    new = _next_bands(ch, cv, new, config, (height, width))
    Ph, keep_h = clean_profile(stripe_points(sensor, ch, 0, 0, dtype), ch.valid, config)
    Pv, keep_v = clean_profile(stripe_points(sensor, cv, 1, 1, dtype), cv.valid, config)
    fh, fv, junction = weld_features(Ph, keep_h, Pv, keep_v, config.weld)
    brightness, saturated = frame_stats(rgb, dtype, config.stats_stride)
    result = FrameResult(
        centres_h=ch,
        centres_v=cv,
        points_h=Ph,
        points_v=Pv,
        feature_h=fh,
        feature_v=fv,
        junction=junction,
        med_steps=steps,
        kurtosis=kurt.astype(dtype),
        used_roi=used_roi,
        brightness=brightness,
        saturated=saturated,
    )
    return result, new


def _check_frame(sensor: Sensor, rgb) -> None:
    width, height = sensor.camera.image_size
    if rgb.ndim != 3 or rgb.shape[-1] != 3:
        raise ValueError(f"expected an RGB frame of shape (H, W, 3), got shape {rgb.shape}")
    if rgb.shape[:2] != (height, width):
        raise ValueError(
            f"frame is {rgb.shape[1]}×{rgb.shape[0]} px but the calibration is {width}×{height}"
        )
    if rgb.dtype != jnp.uint8:
        raise ValueError(f"expected a uint8 frame, got dtype {rgb.dtype}")


@functools.partial(jax.jit, static_argnames=("roi",))
def _process_frame(sensor, config, rgb, state, roi):
    return _process(sensor, config, rgb, state, roi)


def process_frame(
    sensor: Sensor,
    config: PipelineConfig,
    rgb: UInt8[Array, "h w 3"],
    state: PipelineState,
    *,
    roi: bool = True,
) -> tuple[FrameResult, PipelineState]:
    """Run the whole pipeline on one RGB frame (module docstring), jit-compiled.

    Args:
        sensor: the calibrated sensor (its image size must match the frame).
        config: `PipelineConfig` (static: a new config compiles a new program).
        rgb: (H, W, 3) uint8 RGB frame.
        state: `PipelineState` from `init_state` or the previous frame.
        roi: allow tracking mode (bands around the last stripes); False always processes the
            full frame (still warm-starting MED from `state`).

    Returns:
        (`FrameResult`, the state for the next frame).
    """
    rgb = jnp.asarray(rgb)
    _check_frame(sensor, rgb)
    return _process_frame(sensor, config, rgb, state, roi)


#: Names of the entries of `frame_summary`, in order.
SUMMARY_FIELDS = (
    "h_found",
    "h_x_mm",
    "h_y_mm",
    "h_z_mm",
    "h_width_mm",
    "h_height_mm",
    "h_confidence",
    "v_found",
    "v_x_mm",
    "v_confidence",
    "junction",
    "med_steps_h",
    "med_steps_v",
    "used_roi",
    "n_valid_h",
    "n_valid_v",
    "brightness",
    "saturated",
)


def frame_summary(result: FrameResult) -> Float[Array, " k"]:
    """The few numbers a tracker needs from a frame, as one small vector (`SUMMARY_FIELDS`).

    One device→host transfer of this vector per frame is all the tracker's I/O.
    """
    fh, fv = result.feature_h, result.feature_v
    dtype = fh.confidence.dtype
    vals = [
        fh.found,
        fh.centre[0],
        fh.centre[1],
        fh.centre[2],
        fh.width,
        fh.height,
        fh.confidence,
        fv.found,
        fv.position,
        fv.confidence,
        result.junction,
        result.med_steps[0],
        result.med_steps[1],
        result.used_roi,
        jnp.sum(result.centres_h.valid),
        jnp.sum(result.centres_v.valid),
        result.brightness,
        result.saturated,
    ]
    return jnp.stack([jnp.asarray(v).astype(dtype) for v in vals])
