"""`PipelineConfig`: the settings of the per-frame pipeline (`cslx.runtime.pipeline`).

Every field is static: it shapes the compiled program. The docstring records, field by
field, the evidence for each default.
"""

from __future__ import annotations

import equinox as eqx

from ..segmentation.med import default_filter_length
from .weld import WeldConfig

__all__ = ["PipelineConfig", "tracking_config"]


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
        for the full frame; roi_max_steps for the tracking bands (with ``roi_med_lag``
        off): the band filter is carried
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
        then applied to all of them, shifted back by the delay measured on those same
        segments (`cslx.segmentation.med.med_output`; measuring it again on the whole frame,
        `med_apply`, cost a statistics pass and a ridge search more, ≈ 2–3 ms of the cold
        full frame; on the dev frames below, frame 0 of each red-laser condition, centres
        moved by median 0.0013 px, p99 0.014 px, max 0.50 px on a few columns of one
        saturated-sunny frame whose p95 error is 95 mm either way). One filter serves
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
        24 / 40 (48 rows = 3 ``L_roi``, 80 columns = 5 ``L_roi``; 32 / 64 before, issue 13,
        `experiments.band_width`, one process per seed block, the same frames in the same
        order): on a rigid sensor the stripes move in the image only with depth. Over the
        development T approaches (seeds 7301, 7302, 7305, both placements, every nuisance:
        24 runs of 48 frames) the horizontal stripe's 98th-percentile distance from the
        previous frame's median centre was at most 4.3 px; the vertical stripe's from the
        previous frame's line (its band follows a leaning stripe, `band_lean`) at most
        9.1 px but in two flank-sunny runs (29.0, 30.6 px at their worst frame); a band of
        24 holds the stripe within ±16 px of its centre before ``roi_margin`` ends
        tracking. Every frame after the first ran in the bands with either setting (roi
        share 1.000 in every run). The `Tracker` with MED in the bands
        (``config=PipelineConfig(...)``), 32 / 64 → 24 / 40, means over the 24 runs:
        offset error mean 0.1510 → 0.1476 mm, max 0.700 → 0.697 mm, heading 0.265 →
        0.253°, T recall 98.4 → 99.0 %, false T frames 7 → 7 (all in 7305 flank glare);
        with its own pipeline (`tracking_config`): 0.1051 → 0.1047 mm, 0.490 → 0.477 mm,
        0.220 → 0.210°, T 99.1 → 99.1 %, false T 0 → 0 (24 / 48 gave every one of these
        figures as 24 / 40). Band − full-frame MED centres on carried sunny video (dev seeds
        0 / 1 / 555, 24 frames, worst |median| over every third frame and both stripes;
        goal 0.05 px): 0.0204 / 0.0108 / 0.0090 → 0.0217 / 0.0116 / 0.0091 px (20 / 32:
        0.0300 / 0.0123 / 0.0096); median |centre − truth| 0.0980 / 0.1078 / 0.1043 →
        0.0962 / 0.1083 / 0.1061 px; tracking share 1.00 on each.
        Tracking mode (interleaved, one process, 300 frames each, sunny video seed 0, load
        6–7): median paired ratio against 32 / 64 0.912 (24 / 48), 0.853 (24 / 40), 0.875
        (20 / 40), 0.872 (20 / 32), p10 5.46 → 4.74 / 4.51 / 4.58 / 4.69 ms.
        `experiments.ab_tracking --rev 879e4fc` (300 frames, load 8.8–10.6): median 13.54
        → 11.99 ms, p10 5.55 → 4.72, process CPU 8.21 → 7.12 ms, paired −0.768 ms, faster
        in 62 % of the frames; again at load 4.9–3.2: median 4.83 → 4.23 ms, p10 4.14 → 3.42,
        process CPU 6.78 → 5.92 ms, paired −0.638 ms (quartiles −0.969 / −0.268), faster in
        84 % of the frames; at load 0.2–1.4: median 5.53 → 4.68 ms, p10 4.60 → 3.87, process
        CPU 7.68 → 6.62 ms, paired −0.790 ms (quartiles −1.189 / −0.402), faster in 89 %;
        ``--program tracker-med`` (load 1.4–1.5): median 5.89 → 5.22 ms, p10 4.76 → 4.11,
        paired −0.761 ms, faster in 88 %. Rolled projector (`experiments.band_lean_check`'s
        rig, fresh dev seed 7550, 8 frames, `tracking_config`): 25° and 8° both ran 7 of 7
        tracking frames in sheared bands with either setting, the same share found (h 99.9 %,
        v 100 %), h band − full identical; v median 0.0306 → 0.0328 px (25°), max 0.000 →
        0.165 px (8°). The closed loop on a rolled rig was not rerun.
    roi_margin: a stripe closer than this to its band's edge ends tracking mode.
    roi_lean: a stripe that does not fit its straight band gets a band that follows its
        fitted line (`cslx.runtime.band_lean`, a rolled projector; issues 12 / 13) when
        ``roi_lean_fraction`` of its valid centres lie inside that band (evidence there).
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
    roi_med_lag: on a tracking frame, band MED takes one lagged step (`cslx.segmentation.med.med`,
        ``lag=True``; ``roi_max_steps`` unused there): the band is filtered with the filter
        carried from the previous frame, and the one fixed-point step from it, which needs
        that filter's output statistics anyway, is carried to the next frame. Per band 4 FFT
        passes instead of 7 (2 steps: 2 × 2 for the steps, 1 for the final statistics, 1
        for the output; the first-pass frames still converge). Issue 13, tracking carried
        over 24 rendered sunny video frames, band − full-frame MED centres, worst |median|
        over 8 frames × 2 stripes: dev video seed 0 0.0220 px (2 steps 0.0220, 1 step
        0.0220), seed 1 0.0096 px (0.0092, 0.0096); median |centre − truth| 0.1000 / 0.1100
        px (2 steps 0.0985 / 0.1113); experiments/bench_speed.py's agreement on seed 0
        unchanged for the default band filters (0.022 px; free filters 0.169 → 0.206 px).
        Tracking mode (experiments.ab_tracking, 300–400 interleaved frames, load 4–11)
        against 2 steps: median 14.32 → 12.35, 8.53 → 7.90, 12.19 → 10.99 ms, p10 7.40 →
        5.98, 6.58 → 5.66, 6.81 → 5.87 ms; against ``roi_max_steps=1`` without the lag
        10.10 → 9.31 ms (p10 6.52 → 5.92).
    roi_lag_stride: the lagged band step's statistics and fixed-point step on every k-th pair
        of segments (columns of the row band, rows of the column band; `cslx.segmentation.med.med`
        ``lag_stride``: only those pairs are Fourier transformed, and the band is filtered
        whole by one matrix product, `cslx.segmentation.med_fft.shift_matrix`). 4 (default,
        since 5 Dec; 2 before): the step's inverse FFT, its cubes' FFTs and the statistics
        run on a quarter of the band (the reported kurtosis is that of those segments). Once
        the band cut and the weld features got faster
        (issue 13), 4 paid: tracking mode 2.60 → 2.50 and 2.84 → 2.75 ms (8: 2.71), 400
        frames each, calls interleaved, quiet machine (load 1.1–1.3; `experiments/lag_stride.py`);
        band − full-frame MED centres over 8 carried tracking frames × 2 stripes, worst
        |median|, sunny video dev seeds 0 / 1 / 555: 0.0204 / 0.0110 / 0.0086 px with 2,
        0.0204 / 0.0107 / 0.0087 with 4 (8: 0.0204 / 0.0103 / 0.0080); median |centre −
        truth| 0.0970 / 0.1087 / 0.1052 → 0.0972 / 0.1097 / 0.1049 px. When 2 became default:
        Issue 13, tracking mode (experiments.ab_tracking against 1, interleaved frames):
        median 4.02 → 3.73 ms, p10 3.34 → 3.13 (500, load 1.5–1.7); 4.09 → 3.87, p10 3.39 →
        3.24 (600, load 6); band MED alone (800 interleaved calls, load 6) 64×640 0.416 →
        0.346 ms, 480×128 0.763 → 0.509 ms. Band − full-frame MED centres over 22 carried
        tracking frames × 2 stripes (sunny video, dev seeds 0 / 1 / 3), worst |median|:
        0.0216 / 0.0110 / 0.0222 px with 1, 0.0215 / 0.0110 / 0.0222 px with 2 (seed 1
        glare / shadow / clean 0.0138 / 0.0116 / 0.0132 → 0.0134 / 0.0122 / 0.0130 px);
        median |centre − truth| 0.0952 / 0.1099 / 0.0976 px with 1, 0.0952 / 0.1098 /
        0.0978 px with 2. Centres against 1 over 24 frames (seed 0): median |difference|
        2e-4 px, one valid flip in 26 880, one column whose strongest ridge changed; the
        bead position per frame median 4e-4 mm, max 0.125 mm. 4: band MED alone 0.346 →
        0.314 / 0.509 → 0.482 ms, but tracking 3.79 → 3.74 ms (600, load 7.6–9: noise).
    roi_med_alternate: on a tracking frame only one band's filter takes its lagged step, the
        horizontal stripe's and the vertical stripe's in turn (`PipelineState.turn`; the
        other band is filtered with its carried filter and reports 0 steps and a NaN
        kurtosis; `cslx.segmentation.med.med` ``refresh``, a `lax.cond`): each filter steps
        every other frame. Issue 13, on by default: faster, centres within the goal, the
        tracker's accuracy unchanged within its run-to-run spread (experiments/band_alternate.py,
        dev sunny video seeds 0 / 1 / 555, 24 carried frames): band − full-frame MED, worst
        |median| 0.0204 / 0.0107 / 0.0087 → 0.0204 / 0.0108 / 0.0090 px (goal 0.05);
        median |centre − truth| 0.0972 / 0.1097 / 0.1049 → 0.0980 / 0.1078 / 0.1043 px;
        centres against every frame's steps median |Δ| 6.7e-4 / 1.3e-3 / 6.1e-4 px, found
        by one run only 8 / 13 / 12 of ≈ 26 700 (a few columns pick another ridge: max
        24 / 91 / 47 px). The `Tracker` with MED in the bands on 30 development approaches to
        a T (``--sequences 7301 7302 7305 7530 7531``: both placements, sunny / clean /
        shadow): offset error mean 0.1393 → 0.1405 mm (9 runs better, 11 worse, 10 equal to
        the printed digit), heading 0.249 → 0.254°, T recall and false T identical in every
        run. Tracking mode, interleaved on seed 0: median 6.267 → 5.942 ms, p10 4.266 →
        4.108, paired −0.160 ms (300 frames, load 7.8–8.3); against ``HEAD`` 6e3163b
        (`experiments.ab_tracking`, 300 frames, load 6.7–9.4) median 10.45 → 10.28 ms, p10
        6.45 → 6.23, paired −0.354 ms (quartiles −2.56 / +1.85); again on seed 0 (400
        frames, load 11.4–11.6) median 8.273 → 8.046 ms, p10 5.130 → 4.839, paired −0.173.
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
        (`tracking_config`) uses 1 / axes 1 / min run 7 / white 0.5,
        which over the 48 dev T approaches took the runs missing an issue-12 goal from 32
        to 15. Every setting tried helped sun and shadow but made glare worse (experiments/
        tracking_diagnostics.py's docstring; e.g. 1 / axes 1 / min run 7 / white 0.5: sunny
        offset mean 0.218 → 0.125 mm, max worst 3.09 → 1.51 mm, heading 0.520 → 0.328°;
        glare 0.101 → 0.116 mm, max worst 1.10 → 1.50 mm, heading 0.301 → 0.346°). On the
        tracker's first pass (every ``first_pass_stride``-th column) ``clip_dome_along``
        counts strided columns.
    clip_weight / clip_weight_run: the weight, in the horizontal stripe's bead fit (the cap
        model, `cslx.runtime.weld.stripe_feature`), of a centre on a clipped run longer than
        ``clip_weight_run`` px down its column or on a clipped run with a white pixel
        (`cslx.runtime.pipeline._clip_weights`); 1 = off (the paper's pipeline). Evidence
        in `tracking_config`.
    edge_weight / edge_weight_ratio / edge_weight_gap: the weight, in the same fit, of a
        centre where the subtracted channels (the background's estimate) change across the
        stripe by more than ``edge_weight_ratio`` × the laser channel at the centre, sampled
        ``edge_weight_gap`` px to either side (`cslx.segmentation.clipped.background_step`:
        a shadow edge or glint along the stripe); 1 = off (the paper's pipeline). Evidence
        in `tracking_config` (0, 0.5, 6 px there). edge_weight_ramp: > 0 (and below the
        ratio), the weight falls linearly from 1 at a step of ``edge_weight_ramp`` to
        ``edge_weight`` at ``edge_weight_ratio`` instead of jumping there (off; tried
        at 0.25 in `tracking_config` and not kept, the evidence there).
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
    roi_med_lag: bool = eqx.field(static=True, default=True)
    roi_lag_stride: int = eqx.field(static=True, default=4)
    roi_med_alternate: bool = eqx.field(static=True, default=True)
    tol: float = eqx.field(static=True, default=1e-2)
    sigma: float = eqx.field(static=True, default=2.0)
    threshold: float = eqx.field(static=True, default=0.1)
    snr: float = eqx.field(static=True, default=5.0)
    roi_half_h: int = eqx.field(static=True, default=24)
    roi_half_w: int = eqx.field(static=True, default=40)
    roi_margin: int = eqx.field(static=True, default=8)
    roi_lean: bool = eqx.field(static=True, default=True)
    roi_lean_fraction: float = eqx.field(static=True, default=0.95)
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
    clip_weight: float = eqx.field(static=True, default=1.0)
    clip_weight_run: int = eqx.field(static=True, default=7)
    edge_weight: float = eqx.field(static=True, default=1.0)
    edge_weight_ratio: float = eqx.field(static=True, default=0.5)
    edge_weight_gap: int = eqx.field(static=True, default=6)
    edge_weight_ramp: float = eqx.field(static=True, default=0.0)
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


def tracking_config():
    """The tracker's default pipeline: `PipelineConfig` without MED (Steger on R − G).

    Why (issue 12; rendered passes at dev seed 1201, 48 frames per nuisance kind, odometry,
    `experiments/tracking_sequences.py`): offset error mean / max with MED 0.17 / 0.40 mm
    (glare), 0.089 / 0.22 (shadow); without 0.080 / 0.32, 0.075 / 0.18 (clean 0.076 / 0.19).
    Centres in bead columns (seed 101): median 0.150 → 0.125 px (clean), 0.38 → 0.13 px (sun),
    where MED's filter moves the stripe under the bead's sheen. MED stays the default of
    `PipelineConfig` (the paper's method, Table 6).

    MED in the bands, re-measured (2026-12-05, issues 12 / 13; band MED since linear-phase,
    ridge delay, lagged step, ``roi_lag_stride`` 2; fill and weights as below): this config
    with ``use_med=True`` (bands on every frame, MED 2.4 steps a frame h + v, first passes
    converged) against it, experiments/tracking_diagnostics.py ``--variant use_med=False
    --variant use_med=True``, one process. 48 dev T approaches (seeds 7301, 7302, 7305,
    1201–1203), per kind offset mean / max averaged over the runs / worst max mm, heading
    mean °, without → with: clean 0.083 / 0.375 / 0.69 / 0.147 → 0.076 / 0.332 / 0.60 /
    0.151, sunny 0.107 / 0.422 / 0.86 / 0.223 → 0.110 / 0.459 / 0.87 / 0.179, glare
    0.100 / 0.447 / 1.46 / 0.187 → 0.099 / 0.407 / 0.80 / 0.195, shadow 0.091 / 0.445 /
    0.90 / 0.174 → 0.093 / 0.433 / 0.89 / 0.171. Runs meeting every goal 47 → 46: 7305
    flank glare offset max 1.46 → 0.51 mm met, but a false T there (0 → 7 frames, confirmed
    at 209 mm, 11 mm short of the bar: the default measures a crossing bead there too,
    frames 9, 10, 13, but does not confirm it), 7301 flank glare T recall 93.1 → 79.3 %. Seeds
    1204–1206 (24 runs): clean 0.081 / 0.388 / 0.70 / 0.170 → 0.080 / 0.374 / 0.63 / 0.167,
    sunny 0.125 / 0.412 / 0.62 / 0.183 → 0.123 / 0.422 / 0.64 / 0.251, glare 0.091 / 0.311
    / 0.45 / 0.159 → 0.103 / 0.368 / 0.51 / 0.178, shadow 0.083 / 0.391 / 0.69 / 0.173 →
    0.087 / 0.426 / 0.66 / 0.161; runs meeting every goal 22 → 23 (1205 flank sunny false T
    8 → 0 frames; 1205 flank glare recall 81.8 % and false T 14 → 8 frames, missed both
    ways). Tracker step, median of the runs' medians (load ≈ 5, same process, the
    diagnostics' profile copies included): 5.25 → 7.34 ms (48 runs), 4.47 → 7.63 ms (24);
    per run ×1.37 / ×1.50. So band MED no longer costs accuracy (the 2026-11-30 numbers
    above are out of date), but over 72 runs it gains none either (goal misses 4 → 4; with MED
    all 4 are T reports in glare) for ≈ 2–3 ms a frame: the tracker stays without it.

    The clipped-core fill is domed (`PipelineConfig.clip_dome*`: height 1, down the columns
    only, runs longer than 7 px, at most half of a run's pixels white): on sunlit bead
    flanks the red channel clips over 8–14 rows, and the flat fill left a plateau with no
    ridge for Steger. Over the 48 dev T approaches (seeds 7301, 7302, 7305, 1201–1203;
    `experiments/tracking_diagnostics.py`) the runs missing an issue-12 goal went, flat →
    domed: offset mean 10 → 2, offset max 9 → 3, heading 11 → 9, estimate 1 → 0, false T
    1 → 1, T recall 0 → 0; sunny offset mean 0.218 → 0.125 mm, shadow 0.143 → 0.122 mm,
    glare 0.101 → 0.116 mm (worse, but within its goals in as many runs).

    Centres on a clipped run longer than 7 px or holding a white pixel weigh 0.1 in the
    bead's fits (`PipelineConfig.clip_weight`): the fill, not the light, placed them (bead
    columns 0.3–0.9 mm off in height against the renderer's exact stripe, others 0.12–0.14).
    Same 48 runs: missing a goal 15 → 14 (offset max 3 → 2, the rest the same runs); offset
    mean sunny 0.125 → 0.111, glare 0.116 → 0.105, shadow 0.122 → 0.117 mm, worst max sunny
    1.51 → 0.86 mm; heading sunny 0.328 → 0.341°, shadow 0.480 → 0.451°; clean unchanged.

    Centres where the subtracted channel (G) steps across the stripe by more than 0.5 × the
    laser channel at the centre, 6 px to either side, weigh 0 in the same fit
    (`PipelineConfig.edge_weight*`, `cslx.segmentation.clipped.background_step`): where a
    shadow edge runs along the stripe, R clips on the sunlit side and R − G there is
    255 − G, the background's edge, so the ridge sits on the stripe's shadow side (dev seed
    7305 beside shadow, frames 1–7: the bead's flank 0.4–1.4 mm low in height over the
    edge, the bead 1 mm off, and the heading window then 3–5° off for 30 frames). 48 dev
    T approaches (seeds 7301, 7302, 7305, 1201–1203; experiments/tracking_diagnostics.py,
    one process per seed block): runs missing a goal 4 → 3 (goal misses 7 → 6; 1202 beside
    shadow heading 0.510 → 0.176°; 7305 beside shadow offset mean / max / heading 0.387 /
    1.07 / 2.04 → 0.234 / 1.02 / 1.09, still missing; none newly missed); per kind offset
    mean / max averaged over the runs mm, heading mean °: shadow 0.111 / 0.493 / 0.413 →
    0.094 / 0.475 / 0.306, glare 0.1005 / 0.455 / 0.291 → 0.1008 / 0.451 / 0.283 (7305
    beside glare offset mean 0.117 → 0.137 mm), clean and sunny identical; T recall and
    false T identical. A ratio of 0.4 did more for shadow (0.091 / 0.468 / 0.282; 7305 beside
    shadow 0.203 / 0.886 / 0.866) but 7305 flank glare newly missed the heading goal (0.438
    → 0.519°); 0.6 fixed 1202 only (7305 beside shadow 0.280 / 1.08 / 1.37); weight 0.05
    instead of 0 at 0.4 left 7305 beside shadow at 0.315 / 0.928 / 1.55. Figure 22's closed
    loop, dev seed 2201 (`experiments/fig22_tracking.py`, shadow and glare, 31f6b0d → this):
    both turned; shadow steady error mean / max 0.078 / 0.220 → 0.087 / 0.220 mm, after the
    turn 0.035 / 0.065 → 0.048 / 0.131, estimation error mean 0.081 → 0.092 mm; glare steady
    0.081 / 0.214 → 0.125 / 0.630 mm (the turn's end 0.76 mm past the T against 0.16 mm
    short, junction frames 51 → 35), estimation error mean / max 0.066 / 0.195 → 0.073 /
    0.254 mm: within the goals, but no better there.

    A bead one of whose flanks and toes the pipeline weighted out (weight 0) is less
    confident (`WeldConfig.side_cover_power` 2: (min / max of the two sides' shares of kept
    points)²; issue 12, track12e): placed by the other flank alone it was 1.1 mm off (7305
    beside shadow frames 1 and 5, the left flank under the edge, bead 12–14 mm wide for
    16.3) and the filter and the heading window took it at full weight. 48 dev T
    approaches (seeds 7301, 7302, 7305, 1201–1203; experiments/tracking_diagnostics.py,
    one process per seed block, variant against the default): goal misses 5 → 3, runs
    missing one 3 → 3 (7305 beside shadow offset mean / max / heading 0.234 / 1.02 / 1.09
    → 0.192 / 0.686 / 0.536: the heading still missed; none newly missed); only glare and
    shadow runs change (16), per kind offset mean / max averaged over the runs mm, heading
    mean °: glare 0.1008 / 0.451 / 0.283 → 0.1001 / 0.447 / 0.273, shadow 0.0942 / 0.475 /
    0.306 → 0.0912 / 0.445 / 0.260; T recall and false T identical. ⁴: the same misses
    (7305 beside shadow heading 0.510°). The sides' mean prior weights instead of their
    shares of kept points (so that the clip weights 0.1 count): 5 runs (1201 beside sunny
    heading 0.548°). Figure 22's closed loop, dev seed 2201, glare (steady error mean / max,
    estimation error mean / max mm): 0.125 / 0.630, 0.073 / 0.254 → 0.115 / 0.275, 0.107 /
    0.297; shadow 0.087 / 0.220, 0.092 / 0.261 → 0.081 / 0.220, 0.086 / 0.261; sunny
    identical.

    A bead run ends only at a stretch of plate points ≥ 1 mm long, and a point more than
    `threshold_mm` below the plate is no plate point (`WeldConfig.min_plate_mm`,
    `cslx.runtime.bead_run.plate_points`; issue 12, track12m): where the vertical stripe crosses
    the bead (the flank placement) the horizontal stripe's centres dive through the plate's
    height there in sun (fresh seed 7320 flank sunny frames 23 / 25 / 40: a point at plate
    height between dips to −0.4 … −1.3 mm, one at −25.8 mm), the run split, and its larger half
    was fitted: 10–12 mm wide for 18.5, 2.4–3.5 mm off; refitted with the rule, 19.4–20.0 mm
    wide, 0.10–0.26 mm off. `experiments/tracking_diagnostics.py`, each run's variant against
    the default in one process, offset mean / max mm, heading mean °, before → after. Fresh
    seeds 7320–7322 (sunny and shadow, both placements; 7322 flank shadow not run) and 7326–7327
    flank sunny: 7320 flank sunny 0.351 / 0.873 / 0.422 → 0.144 / 0.625 / 0.220, 7320 flank
    shadow 0.164 / 0.665 → 0.128 / 0.665, 7327 flank sunny 0.157 / 0.874 → 0.094 / 0.856, 7320
    beside sunny 0.179 / 0.900 → 0.170 / 0.900 (its max is frame 0, whose sunlit flank has no
    points at all: not this), 7321 beside sunny 0.143 / 0.571 → 0.094 / 0.597, 7321 flank sunny
    0.157 / 0.536 → 0.149 / 0.474; the other 7 within ±0.004 mm. Dev runs (32 of the 72: 7301,
    7302, 7305 flank, every kind; 1201–1206 sunny, both placements; 1205 and 1206 glare /
    shadow, both): 1205 flank sunny 0.177 / 0.622 / 0.346 → 0.126 / 0.622 / 0.149, 1206 flank
    sunny 0.135 / 0.421 → 0.100 / 0.240, 1206 flank glare 0.114 → 0.100, 1202 flank sunny 0.122
    → 0.093, 1201 beside sunny 0.143 / 0.447 → 0.115 / 0.563, 7305 flank glare 0.116 → 0.106
    (max 1.46, frame 0, unchanged); worse: 7302 flank sunny 0.111 / 0.863 / 0.446 → 0.129 /
    0.832 / 0.502 (its heading newly 0.002° over the goal; the same with 0.5 mm, so the points
    below the plate, not the stretch length), 7305 flank sunny heading 0.403 → 0.456°, 1206
    beside glare 0.262 → 0.372°, 1205 beside glare 0.071 / 0.235 → 0.078 / 0.275 mm; the others
    within ±0.005 mm; T recall and false T identical in every run (the vertical stripe's
    junction search is not changed).

    Not kept: the edge weight falling linearly from 1 at a step of 0.25 to 0 at 0.5
    (`PipelineConfig.edge_weight_ramp` 0.25; a step below 0.5 still biases the centre: 7305
    beside shadow frames 13 and 20, steps 0.35–0.45 under the flank facing the sunlit side,
    heights 0.2–0.4 mm low). With the side factor ² it took the 48 runs to 2 runs / 2
    misses (7305 beside shadow 0.173 / 0.563 / 0.375; glare 0.0961 / 0.450 / 0.275, shadow
    0.0896 / 0.435 / 0.245; 7305 flank glare heading 0.440 → 0.482°; a ramp from 0.35: 3
    runs, 1201 flank glare 0.517°), but Figure 22 (2201, glare) went astray after the turn
    with it, alone or with the side factor: estimation error mean / max 0.256 / 1.327 and
    0.266 / 1.242 mm (the estimate swung from +1.2 to −1.2 mm on the bar's first 12
    frames), junction frames 34 → 50 / 53.
    """
    return PipelineConfig(
        use_med=False,
        clip_dome=1.0,
        clip_dome_axes=1,
        clip_dome_min_run=7,
        clip_dome_white=0.5,
        clip_weight=0.1,
        clip_weight_run=7,
        edge_weight=0.0,
        edge_weight_ratio=0.5,
        edge_weight_gap=6,
        weld=WeldConfig(junction_min_confidence=0.1, side_cover_power=2.0, min_plate_mm=1.0),
    )
