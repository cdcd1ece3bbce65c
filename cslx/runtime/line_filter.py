"""The tracker's weld-line filter: Kalman filter over (offset e, heading θ), re-acquiring gates.

The model, the prediction from odometry, the update with the horizontal stripe's bead centre and
the gating that re-acquires are described in `cslx.runtime.tracker`'s module docstring; this
module holds the filter and its tuning (`KalmanConfig`) so that the tracker stays short.
"""

from __future__ import annotations

import dataclasses
import math
import statistics

import numpy as np

from . import filter_start

__all__ = ["KalmanConfig", "WeldLineFilter", "carry", "robust_line", "width_weight"]


def carry(x, y, d: float, delta: float):
    """Wall points (x_r, y_r) seen from the robot after it moved d mm and turned δ rad (CCW +):
    (cos δ (x − d) + sin δ y, −sin δ (x − d) + cos δ y). Scalars or arrays."""
    x = x - d
    c, s = math.cos(delta), math.sin(delta)
    return c * x + s * y, -s * x + c * y


@dataclasses.dataclass(frozen=True)
class KalmanConfig:
    """Tuning of the weld-line filter (module docstring). mm, rad, frames."""

    q_offset: float = 0.08  # mm per √mm travelled
    q_heading: float = 0.002  # rad per √mm travelled
    q_floor: float = 1e-4  # mm², rad² per frame (a robot at rest drifts a little too)
    sigma_meas: float = 0.35  # mm, at confidence 1
    init_offset_std: float = 2.0  # mm
    init_heading_std: float = math.radians(10.0)
    gate: float = 4.0  # innovation standard deviations
    reset_after: int = 3  # mutually consistent rejected measurements in a row → restart
    consistent_mm: float = 1.0  # half their spread (max − min) at x_ref, mm
    give_up_after: int = 8  # rejected measurements in a row that restart it regardless
    # the last `trend_after` rejected centres, at x_ref along the current heading, on a
    # straight line in time (each within `consistent_mm` of their least-squares line) also
    # restart it, at the line's latest value (`WeldLineFilter._trend`): a prediction that
    # lags a steady lateral drift (faster lateral motion than the filter expects, a turn
    # seen without odometry) rejects the truth frame after frame while it moves on, so the
    # rejected centres never agree on one offset and only `give_up_after` ended the lock-out.
    # Rendered video through the turn at a T without odometry (`cslx render --scene video
    # --laser-colour green --nuisance sunny --frames 30 --seed 555`, `cslx track --dry-run`):
    # after the followed weld changed, 8 → 4 frames locked out, offset error max 18.5 →
    # 9.0 mm, mean over the video 3.74 → 1.78 mm. 16 dev tracking sequences (7301, 7305,
    # both placements, every nuisance, odometry): identical (no trend restart). Figure 22's
    # closed loop, dev seed 2201 (`experiments/fig22_tracking.py`): glare identical; sunny
    # steady error mean 0.132 → 0.144 mm, after the turn 0.126 → 0.143 mm (max unchanged,
    # 0.579), estimate error mean 0.148 → 0.189 mm: a small cost, kept for the lock-outs it
    # ends. 3 centres instead of 4 would take any three within ±1 mm of a line, glints
    # included; 0: off. Only on frames without odometry (`WeldLineFilter.predict`): with
    # the motion measured a lagging prediction is not the robot's own motion, and the trend
    # restart cost the closed loop more (dev seeds 2203 / 2204, sunny and shadow, steady
    # error mean with the trend on every frame → off: 2203 sunny 0.126 → 0.100, shadow
    # 0.500 → 0.179 mm (after the turn 0.629 → 0.176, max 1.112 → 0.733); 2204 sunny 0.564
    # → 0.314 (max 1.556 → 1.361), shadow 0.072 → 0.068 mm; deterministic runs)
    trend_after: int = 4
    # a restart takes its heading from the rejected centres when they span this much and
    # contradict the current heading (`WeldLineFilter._restart_heading`); 0: keep the heading.
    # Figure 22's closed loop, sunny, dev seeds 2201 / 2203 / 2204 (`experiments/
    # fig22_tracking.py`), error after the turn mean keeping the heading → with: 0.356 →
    # 0.280, 0.258 → 0.070, 0.529 → 0.195 mm (max 0.810 → 0.715, 0.516 → 0.164, 1.103 →
    # 0.296); stem unchanged; 2204 shadow 0.385 → 0.204. With the old heading (≈ 90° off
    # after re-acquiring the bar during the turn) the estimate ran 2.7 mm off over the first
    # 10 frames on the bar at 2204. 44 dev tracking sequences (7301, 7302, 7305, 1201–1203):
    # identical. A first version (span ≥ 5 mm, all pending centres or else the last 3) left
    # the closed loop at 2201 and 2204 unchanged: it never replaced the heading there
    restart_heading_span_mm: float = 2.0
    # The heading is reported (`Observation.heading_deg`; NaN otherwise) while its standard
    # deviation, reported with it (`Observation.heading_sd_deg`), is below
    # `heading_valid_deg`: the filter's sd and, with `heading_valid_model`, at least the
    # last fused path window's as the measurement model predicts it from its centres'
    # confidence weights and spacing (`path_heading.predicted_sd`, σ_meas² / conf per centre),
    # grown by q_heading² per mm since (`PathHeading.model_var`; none after a restart). The
    # filter's own sd cannot say when the heading is known: it falls to 0.3–0.6° on the frame
    # the window is first fused, whatever the window's centres (the window's residual sd is
    # scale-free in the weights, and consecutive windows, fused as news every frame, share
    # their centres), so 3°, 1.5° or 1° on it all meant "from the first fused window" or
    # earlier. Issue 12, the 48 dev T approaches (experiments/tracking_diagnostics.py, one
    # process per seed block, filter variants on the same pipeline outputs; confirmed with
    # experiments/tracking_sequences.py), filter sd < 3° → model sd < 0.8°: heading goal
    # misses 2 → 0 (7302 flank shadow 0.633 → 0.450°; 7305 beside shadow 0.536 → 0.273°:
    # its first 13 beads, under a shadow edge, have confidence 0.02–0.08, so the window waits
    # for the confident ones), no run newly missing a goal, offsets and T reports identical
    # (the fused heading is unchanged; only what is reported); heading error mean over the
    # runs 0.267 → 0.182°. The price: a heading on 58.1 % of the frames instead of 79.3 %
    # (mean over the runs; ≈ 10 frames, 15 mm, later in a pass, whose first ≈ 30 mm have
    # none). 1.0 / 1.2 / 1.5°: misses 2 / 2 / 2 (7305 beside shadow met at each, 0.253 /
    # 0.292 / 0.391°; 7302 flank shadow 0.525 / 0.538 / 0.533°, and 7302 flank sunny newly
    # 0.509 / 0.501 / 0.501° against 0.479: the window's first 22–30 mm on a flank whose
    # crossing with the vertical stripe lies on the bead's toe, ±0.5 mm a bead); heading
    # error mean 0.196 / 0.208 / 0.214°. The filter's sd alone below 1.5° or 1° (7301 +
    # 7302): 2 misses (7302 flank shadow 0.533°, flank sunny 0.501°). The reported sd is
    # conservative: RMS of error / reported sd 0.54 over the 1339 frames with a heading
    # (|z| < 1 on 94 %). Figure 22, dev seed 2201 (experiments/fig22_tracking.py), before →
    # after, steady error mean / max mm, all turned: clean 0.111 / 0.239 → 0.132 / 0.295,
    # sunny 0.091 / 0.209 → 0.136 / 0.409, glare 0.144 / 0.762 → 0.121 / 0.554, shadow
    # 0.113 / 0.431 → 0.102 / 0.228 (the max is the first frame after the turn in each,
    # where the coast to the T ended; ±0.6 mm with any change of path, `heading_min_span_mm`).
    # While coasting to the T the heading goes NaN after ≈ 40 mm (the model sd grown past
    # 0.8°) and the controller steers by the offset alone. Not kept: the model sd at the
    # last fuse (not grown) below 0.8° and the filter's below 3° (the heading kept while
    # coasting): the 48 runs the same but 1201 flank sunny (0.328 → 0.317°), Figure 22
    # clean 0.123 / 0.239, sunny 0.271 / 0.437 (estimate error mean 0.157 mm), glare
    # 0.124 / 0.609 mm
    heading_valid_deg: float = 0.8
    heading_valid_model: bool = True
    decay: float = 0.85  # confidence per frame without a bead
    junction_window: int = 10
    junction_tol_mm: float = 6.0
    # `JunctionTrack`: frames a confirmed junction is reported without a new sighting, and
    # how far (mm travelled) the plate where a new junction lies may have been in view
    # without a sighting before it counts as an artefact. Dev seeds 1201 + 1202, 16 passes,
    # the T within 3 mm on the frames in view / false reports per pass: two sightings only
    # 59–97 % / 0–3; hold 4 frames 78–100 % / 0–5 (flank, sun and glare, 1202: bumps fixed on
    # the plate ≈ 40 mm before the bar, and a nearer artefact taking over after 5 frames
    # without the bar); hold 6: 78–100 % / 0–4; hold 6 and unseen 20 mm (or 15): 78–100 % / 0.
    # A third dev seed, 1203 (flank, glare): a junction confirmed by two 1.0 mm bumps at the
    # start (no history to call them unseen) and held 6 frames gave 7 false reports; holding
    # only once 3 sightings support it: 1 (recall 100 → 96.9 %; clean 96.9 → 93.8 %, 0 → 1
    # false unchanged; seeds 1201 + 1202 unchanged but flank clean and glare 1201 100 → 97 %)
    junction_hold: int = 6
    junction_unseen_mm: float = 20.0
    junction_hold_min_support: int = 3
    # sightings of a crossing weld at x_r within x_ref + this range (where the stripes cross)
    # do not move a junction that sightings outside it support; its position is the median
    # of the last `junction_keep_clear` sightings made outside (`JunctionTrack`, "where the
    # stripes cross"). Dev seeds 7301, 7302, 7305, 12 rendered approaches from x_j = 190 mm
    # (beside and flank, sun and clean; the stored sequences end at 164 mm, before the zone):
    # sightings at 140–145 mm were 3.9 mm too far on average (1.3 mm at 145–150), elsewhere
    # −1.4 to +0.9 mm by 5 mm bin. Reported junction, mean error / max |error|, without →
    # with (−40, 12) and 30 kept: x_j 120–140 mm 0.76 / 2.01 → 0.08 / 1.11, 140–150 mm
    # 0.52 / 1.86 → 0.19 / 1.12, 150–160 mm −0.27 / 1.84 → 0.25 / 1.06, beyond 160 mm
    # unchanged; the last report (what the controller dead-reckons to the T from) ≤ 1.83 →
    # ≤ 0.89 mm off. (−30, 10): 140–150 mm 0.05 / 1.12 but a last report 0.97 mm off; 10
    # kept instead of 30 (9 of the approaches): a last report 1.24 mm off
    junction_crossing_zone_mm: tuple[float, float] = (-40.0, 12.0)
    junction_keep_clear: int = 30
    # how those sightings make one position: "median", or "mean" (of those within
    # `junction_tol_mm` of the median; `JunctionTrack._fused`). Issue 12, Figure 22 dev
    # seeds 2201/2203/2204: not the default (offline evidence only, see the branch report).
    # 48 dev T approaches (experiments/tracking_diagnostics.py): T recall and false T the
    # same in every run, the reported T farther off ("mean" → mean |error| over the
    # reporting frames, averaged per kind: clean 0.326 → 0.430, sunny 0.405 → 0.459, glare
    # 0.369 → 0.413, shadow 0.318 → 0.385 mm)
    junction_fuse: str = "median"
    # A crossing bead lower than this is not a weld: on rendered straight-weld frames the
    # full-frame pass showed 0.6 mm, 13 mm wide bumps on the bare plate (segmentation
    # artefacts) that the detector took for a crossing bead; weld reinforcement is 1–3 mm.
    # Dev seeds 1201 + 1202 (16 passes): all 419 sightings within 3 mm of the truth were
    # ≥ 1.01 mm high; 25 false sightings were lower (0.8 let them through).
    junction_min_height_mm: float = 1.0
    # A crossing bead cut by the far end of the vertical stripe's view is no sighting: its
    # far toe (x + width / 2, both as measured) within this of the stripe's measured far end
    # (`Tracker._junction`; < 0: off). Its centre is then the visible part's: dev seed 7305,
    # flank, glare, frames 9–10, the bar's centre 221 / 220 mm beyond the view's end at
    # 219.4 mm, sightings at 209.7 / 211.0 mm (far toes 219.3 / 218.6 mm) confirmed a T 10 mm
    # short (the dev runs' one false T frame); once the whole bar was in view (frame 19 on)
    # its far toe lay ≥ 2 mm inside the end. Off by default: 48 dev runs (one process, with
    # `heading_min_span_mm` 22), margin 1 mm against off: that false T gone, but 7301 flank
    # glare newly missed the T goals (1 false T frame, recall 86.2 %), runs missing a goal
    # 7 → 8, every other score identical; Figure 22 (dev seed 2201) clean, sunny, shadow
    # identical, glare steady error mean / max 0.087 / 0.296 → 0.238 / 1.204 mm (the turn's
    # end position: the last reports before the coast to the T changed)
    junction_cut_margin_mm: float = -1.0
    # sightings that agree (within `junction_tol_mm`, last `junction_window` frames) needed
    # to confirm a new junction (`JunctionTrack`, "confirm"; at least 2). Dev seed 7305,
    # flank, glare, frames 7–12: glare gave one sighting a frame, scattered (199.4, 161.4,
    # 209.7, 211.0, 105.7, 113.1 mm), two of which (209.7 / 211.0, the bar's near toe while
    # its centre, 220 mm, lay beyond the view's end) agreed and made the dev runs' one false T
    # frame, 10 mm short. 48 dev runs (experiments/tracking_diagnostics.py, one process per
    # block, kalman variant; confirmed with experiments.tracking_sequences before / after)
    # 2 → 3: that false T gone, no run gains a miss (goals missed 7 → 6; runs missing one
    # stay 3: 7305 flank glare keeps its offset max, 1.46 mm on frame 0), every offset and
    # heading score identical; the first report comes a frame
    # later, T recall 100 → 96.9 % in 1201 and 1202 flank sunny, 96.6 → 93.1 % in 7301
    # beside clean, 96.9 → 93.8 % in 1203 flank sunny and shadow (minimum 93.1 %)
    junction_confirm_min: int = 3
    # the held junction's position from the line through its sightings' plate points (the
    # crossing weld's centre line, odometry-carried) where it meets the stripe now, not the
    # median of their x_r (`JunctionTrack`, `bar_slope`): a bar at an angle other than 90°
    # slides along the stripe when the robot turns (issue 12 audit, fresh seed 7400, T at
    # 60°: the reported T up to 9 mm behind the sightings)
    junction_bar_slope: bool = True
    # with fewer than 10 (`JunctionTrack.bar_min_points`) but at least this many points, the
    # bar's line only if its slope is ≥ `junction_bar_oblique_deg` from square, beyond 3σ,
    # and nearer the newest sighting than their median (`JunctionTrack._on_bar`; None: off).
    # Replays: fresh seed 7400 T at 120° clean 66.7 % / 3 false T frames → 100 % / 0, sunny
    # 55.6 % / 7 → 100 % / 3; 12 dev runs' T scores identical (`cslx.runtime.junction_track`)
    junction_bar_oblique_points: int | None = 6
    junction_bar_oblique_deg: float = 15.0
    # a bead whose width differs from the median of the last `width_memory` accepted ones by
    # u·width_tol of it (|u| > 1) has its confidence divided by u²: in sunlight a glint that
    # hides a flank makes the bead look narrower or merges it with the plate (widths of 10 to
    # 34 mm for a 14 mm bead at dev seed 1201), and those are the frames whose position is off
    width_tol: float = 0.2
    width_memory: int = 20
    # > 0: on a frame whose bead the gate would reject, refit the bead on the horizontal
    # stripe's points within (half the recent median width + this) of the predicted line and
    # take it if the gate accepts it (`cslx.runtime.bead_near`: the profile's largest bead is
    # another weld, e.g. the bar of a T at 60° or 120°; issue 12 audit there). 0: off
    near_refit_mm: float = 8.0
    # fuse the heading the vertical stripe sees (`weld.heading_from_vertical`). Off: along the
    # bead's flank (dev seed 1201, odometry) the heading error went 0.51° → 1.34° (clean),
    # 0.60° → 1.70° (sun); beside the weld it never sees the weld's direction
    use_vertical_heading: bool = False
    sigma_heading_floor_deg: float = 0.3  # its standard deviation at least this
    # heading from a robust line (`robust_line`, Tukey c = `heading_tukey_c` scales) through
    # the accepted bead centres of the last `heading_window_mm` of travel, carried into the
    # current robot frame by odometry, fused as a heading measurement once they span
    # `heading_min_span_mm`; each centre weighted by its confidence / (1 + (Δw / (tol·m))⁴),
    # Δw its width's departure from the window's median width m (tol = `heading_width_tol`).
    # Dev seeds 1201 + 1202, 16 rendered passes (experiments/tracking_sequences.py, odometry):
    # heading error mean without → with: sun beside 2.74 → 0.90° and 0.38 → 0.35°, sun on the
    # flank 1.07 → 0.75° and 0.84 → 0.22°, 15 of 16 passes better or equal, one worse (1202
    # shadow beside 0.39 → 0.58°); without the width weights (tol 0) sun beside 1201 gave
    # 2.11° and sun on the flank 0.38°; a 90 mm window changed nothing; c = 2 was worse (3.98°)
    heading_window_mm: float = 60.0  # 0: off
    # 22 mm, not 15 (before, the filter's own least-squares line through the same centres;
    # the window's biweight line through its first 10–14 centres is the noisier one): 48 dev
    # T approaches (experiments/tracking_diagnostics.py, one process, at 1592fef; per kind
    # offset mean / max averaged over the runs mm, heading mean °), 15 → 22 mm: clean 0.085
    # / 0.374 / 0.273 → 0.083 / 0.375 / 0.252, sunny 0.108 / 0.421 / 0.281 → 0.107 / 0.422
    # / 0.282, glare 0.101 / 0.456 / 0.315 → 0.101 / 0.456 / 0.291, shadow 0.115 / 0.493 /
    # 0.439 → 0.111 / 0.493 / 0.413; runs missing a goal 12 → 7 (heading 8 → 3, none newly
    # missed; spans 10 / 18 / 26 / 30 mm: 16 / 10 / 6 / 7). It was first not adopted for
    # Figure 22's closed loop (dev seed 2201; sunny steady error mean 0.182 → 0.346 mm at
    # that code), but that loss is not the heading's: the tracker's own error is the same
    # (estimation error mean / max at today's code 15 → 22 mm, clean 0.088 / 0.263 → 0.109 /
    # 0.270, sunny 0.092 / 0.299 → 0.092 / 0.246, glare 0.067 / 0.195 → 0.069 / 0.195,
    # shadow 0.096 / 0.288 → 0.091 / 0.261 mm); the steady error's max and most of its
    # mean is the first frame after the turn at the T (0.01–1.23 mm in these 8 runs), i.e.
    # where the robot ends its in-place turn, set by the junction report made 150–210 mm
    # ahead and dead-reckoned through ≈ 100 frames of coasting. Any change to the path (a
    # heading span, float32 rounding in Steger's filters) moves that by up to ±1 mm: at
    # today's code (after fba7745's padding change alone) 15 mm gives sunny 0.249 / 1.225
    # mm, not 0.182, and 22 mm 0.113 / 0.259. Figure 22, dev seed 2201, steady mean / max
    # 15 → 22 mm, today's code (all turned): clean 0.143 / 0.676 → 0.121 / 0.239, sunny
    # 0.249 / 1.225 → 0.113 / 0.259, glare 0.116 / 0.349 → 0.087 / 0.296, shadow 0.210 /
    # 0.880 → 0.220 / 0.936 mm
    heading_min_span_mm: float = 22.0
    heading_tukey_c: float = 3.0
    # then 8 more iterations at the biweight's textbook cut-off 4.685 (95 % efficiency under
    # Gaussian noise) from the line c = 3 found (`robust_line`'s c_refine; 0: off): with the
    # window's first 6–15 centres c = 3 alone drops good ones and its line is noisier (10
    # centres over 15 mm, 0.3 mm noise, 400 draws: mean |θ error| 1.09°, with the second
    # stage 1.01°, least squares 0.89°), while 4.685 from the start lets a cluster of glint-
    # biased centres pull the line (tests/runtime/test_line_filter.py: 2° → −0.09°). 48 dev
    # T approaches (experiments/tracking_diagnostics.py, one process): runs missing a goal
    # 14 → 12 (heading 9 → 8, offset mean 2 → 1; one new heading miss, 1203 flank clean
    # 0.39 → 0.52°); heading mean clean 0.279 → 0.273, sunny 0.341 → 0.281, glare 0.340 →
    # 0.315, shadow 0.451 → 0.439°; offset mean equal or lower in every kind
    heading_tukey_refine: float = 4.685
    heading_scale_floor_mm: float = 0.15
    heading_width_tol: float = 0.25
    # Off (default): the window's heading is fused every frame as a new independent
    # measurement, although consecutive windows share all but one centre, so the filter's
    # heading sd is too small while the window is short (straight passes at 1.5 mm a frame,
    # the noise `sigma_meas` assumes, frames 10–24: RMS of error / sd 1.83, with this 1.21
    # at a 15 mm span; 1.42 / 0.98 at 22 mm; tests/runtime/test_path_heading.py). On: only
    # the information the window gained since the last fused one is fused
    # (`WeldLineFilter.update_heading`'s gain: 1 / (R_prev + q_heading² · travel since), R
    # at most 1 / `heading_gain_floor` × the window's). 48 dev
    # T approaches (experiments/tracking_diagnostics.py, one process; per kind offset mean /
    # max mm, heading mean °, RMS error / sd averaged over the runs), off → on: clean 0.085 /
    # 0.374 / 0.273 / 0.99 → 0.085 / 0.374 / 0.283 / 0.64, sunny 0.108 / 0.421 / 0.281 /
    # 0.98 → 0.109 / 0.421 / 0.281 / 0.56, glare 0.101 / 0.456 / 0.315 / 1.02 → 0.102 /
    # 0.458 / 0.323 / 0.63, shadow 0.115 / 0.493 / 0.439 / 1.39 → 0.117 / 0.493 / 0.468 /
    # 0.90; goal misses 12 → 12 (the same runs; `heading_min_span_mm` 15). On the rendered
    # runs the default's sd is not too small on average (the bead's real errors are larger
    # than `sigma_meas` at the confidence given) and this one is too large; the estimate is
    # the window's either way.
    # Not kept either: covariance intersection (P / ω, R / (1 − ω), ω minimising det P):
    # offset mean sunny 0.108 → 0.143, glare 0.101 → 0.124 mm, misses 12 → 14 (offset mean
    # 1201 flank sunny and glare); floor 0.3: heading 0.279 / 0.279 / 0.319 / 0.456°
    heading_gain_only: bool = False
    heading_gain_floor: float = 0.1
    # The window's heading standard deviation as the measurement model predicts it (each
    # centre's variance `sigma_meas`² / its weight, the weights `PathHeading` gives them, as
    # in `WeldLineFilter.update`): σ_pred² = `sigma_meas`² / Σ wᵢ (xᵢ − x̄_w)², x̄_w the
    # weighted mean position. `heading_sd_model`: fuse max(the fit's residual sd, σ_pred)
    # (the residual scale of the window's first 6–15 centres is itself noisy and often far
    # below the bead's real error). `heading_max_sd_deg` > 0: fuse only once σ_pred ≤ this,
    # a span requirement that follows the centres' confidence and spacing instead of a fixed
    # `heading_min_span_mm` (at 1.5 mm a centre, confidence 0.6: 15 mm ↔ 1.9°, 22 mm ↔
    # 1.07°, 30 mm ↔ 0.67°). Both off: on the 48 dev runs the model sd changed the heading
    # error by ≤ 0.004° a kind and no goal (the sd then too large, RMS error / sd 0.92 →
    # 0.63); 1.0 / 1.2° from a 6 mm floor on 7302 + 7305 (16 runs): the 22 mm span's misses,
    # heading within 0.02° a kind (experiments/tracking_diagnostics.py).
    heading_sd_model: bool = False
    heading_max_sd_deg: float = 0.0
    # the start (`cslx.runtime.filter_start`; off: on 104 dev runs 3 changed 7743 flank sunny's
    # offset mean 0.187 → 0.196 mm only, the width range traded offset max misses 3 → 1 for
    # estimate misses 0 → 4). ≥ 3: restart on the 2nd to K-th beads from a cold start when
    # they agree and the first does not; < 3: off
    start_agree: int = 0
    # (lo, hi) mm: a cold filter waits for a bead of this width or two agreeing ones; None: off
    start_width_mm: tuple[float, float] | None = None


class WeldLineFilter:
    """Kalman filter over (offset e mm, heading θ rad); see the module docstring."""

    def __init__(self, config: KalmanConfig, x_ref: float):
        self.c = config
        self.x_ref = x_ref
        self.reset()

    def reset(self) -> None:
        self.x: np.ndarray | None = None
        self.P = np.zeros((2, 2))
        self.rejected = 0
        self.restarts = 0
        self.pending: list[np.ndarray] = []  # rejected centres (x_r, y_r), current frame
        self.start_beads: list[np.ndarray] = []  # (x_r, y_r, conf) since a cold start
        self.waiting: tuple[float, float, float] | None = None  # refused first bead (x, y, w)
        self.odometry = False  # the last prediction's motion was measured

    @property
    def initialised(self) -> bool:
        return self.x is not None

    def predict(self, d: float, delta: float, odometry: bool = False) -> None:
        """Advance by d mm and turn by δ rad; `odometry`: measured motion, not the nominal
        speed (it switches the trend restart off, `KalmanConfig.trend_after`)."""
        self.odometry = odometry
        self.pending = [np.array(carry(p[0], p[1], d, delta)) for p in self.pending]
        filter_start.move(self, lambda x, y: carry(x, y, d, delta))
        if self.x is None:
            return
        c = self.c
        F = np.array([[1.0, d], [0.0, 1.0]])
        self.x = F @ self.x + np.array([-self.x_ref * delta, -delta])
        Q = np.diag([c.q_offset**2, c.q_heading**2]) * abs(d) + c.q_floor * np.eye(2)
        self.P = F @ self.P @ F.T + Q

    def start(self, y: float, theta: float = 0.0, theta_std: float | None = None) -> None:
        """(Re)start at offset y, heading θ; heading standard deviation `init_heading_std`
        unless given."""
        c = self.c
        sd = c.init_heading_std if theta_std is None else theta_std
        self.x = np.array([y, theta])
        self.P = np.diag([c.init_offset_std**2, sd**2])
        self.rejected = 0
        self.pending = []
        self.start_beads = []

    def _reacquire(self) -> bool:
        """Restart at the rejected centres if the last `reset_after` agree (docstring)."""
        c = self.c
        recent = np.array(self.pending[-c.reset_after :])
        theta = float(self.x[1]) if self.x is not None else 0.0
        at_ref = recent[:, 1] - np.tan(theta) * (recent[:, 0] - self.x_ref)
        agree = len(recent) >= c.reset_after and np.ptp(at_ref) <= 2.0 * c.consistent_mm
        trend = None if agree else self._trend(theta)
        if agree or trend is not None or self.rejected >= c.give_up_after:
            new, sd = self._restart_heading(np.array(self.pending), theta)
            if new != theta:
                theta = new
                at_ref = recent[:, 1] - np.tan(theta) * (recent[:, 0] - self.x_ref)
                trend = None  # along the line's own heading its centres agree
            if trend is not None:
                y = trend
            elif agree:
                y = float(np.mean(at_ref))
            else:
                y = float(at_ref[-1])
            self.start(y, theta, sd)
            self.restarts += 1
            return True
        return False

    def _trend(self, theta: float) -> float | None:
        """The latest value of the line through the last `trend_after` rejected centres,
        at x_ref along heading θ, as a function of their order; None unless each lies within
        `consistent_mm` of it (`KalmanConfig.trend_after`)."""
        c = self.c
        k = c.trend_after
        if k < 3 or len(self.pending) < k or self.odometry:
            return None
        recent = np.array(self.pending[-k:])
        at_ref = recent[:, 1] - np.tan(theta) * (recent[:, 0] - self.x_ref)
        t = np.arange(k, dtype=float) - 0.5 * (k - 1)
        slope = float(t @ at_ref) / float(t @ t)
        fit = at_ref.mean() + slope * t
        if np.max(np.abs(at_ref - fit)) > c.consistent_mm:
            return None
        return float(fit[-1])

    def _restart_heading(self, points: np.ndarray, theta: float) -> tuple[float, float | None]:
        """The heading to restart with and its standard deviation (None: `init_heading_std`).

        The current heading θ, unless the rejected centres `points` (carried into the
        current robot frame by odometry; the longest recent run of them that lies on one
        line) lie on a line whose direction contradicts it. During the in-place turn at a T
        the centres trace the crossing weld while θ is still the old weld's, ≈ 90° off;
        restarting with that θ made the prediction e' = e + d·θ run off along the new weld
        (module `cslx.runtime.tracker`; numbers in `KalmanConfig`).

        The line is the points' principal direction; its standard deviation is σ / √Σ s²
        (s the points' positions along it, σ the larger of their RMS distance from it and
        `sigma_meas`, at least `sigma_heading_floor_deg`). It replaces θ when the points
        span ≥ `restart_heading_span_mm` along it, lie within `consistent_mm` RMS of it, and
        differ from θ (modulo 180°) by more than `gate` standard deviations of the two
        combined; a lateral jump on a straight pass (three centres 3 mm apart along the
        weld) keeps θ.
        """
        c = self.c
        keep = (theta, None)
        if c.restart_heading_span_mm <= 0:
            return keep
        for k in range(len(points), 2, -1):  # the longest recent run on one line
            q = points[-k:] - points[-k:].mean(axis=0)
            _, sv, vt = np.linalg.svd(q, full_matrices=False)
            s = q @ vt[0]
            rms = float(sv[1]) / math.sqrt(k)
            if np.ptp(s) >= c.restart_heading_span_mm and rms <= c.consistent_mm:
                break
        else:
            return keep
        phi = math.atan2(vt[0][1], vt[0][0])
        delta = (phi - theta + math.pi / 2) % math.pi - math.pi / 2
        sd = max(rms, c.sigma_meas) / math.sqrt(float(s @ s))
        p_theta = float(self.P[1, 1]) if self.x is not None else c.init_heading_std**2
        if delta * delta <= c.gate**2 * (sd * sd + p_theta):
            return keep
        sd = max(sd, math.radians(c.sigma_heading_floor_deg))
        return (phi + math.pi / 2) % math.pi - math.pi / 2, sd  # the line's direction, |θ| ≤ 90°

    def update_heading(self, theta: float, sd: float, gain: float = 0.0) -> bool:
        """Fuse a direct heading measurement (rad, its standard deviation rad); gated.

        gain > 0: the information (1/rad²) already fused from the same evidence (the previous
        path window, `KalmanConfig.heading_gain_only`); only what the measurement adds beyond
        it is fused, R ← 1 / max(1/R − gain, `heading_gain_floor` / R)."""
        if self.x is None:
            return False
        R = max(sd, np.radians(self.c.sigma_heading_floor_deg)) ** 2
        H = np.array([0.0, 1.0])
        nu = theta - self.x[1]
        if nu * nu > self.c.gate**2 * (self.P[1, 1] + R):
            return False
        if gain > 0:
            R = 1.0 / max(1.0 / R - gain, self.c.heading_gain_floor / R)
        S = self.P[1, 1] + R
        K = self.P @ H / S
        self.x = self.x + K * nu
        self.P = (np.eye(2) - np.outer(K, H)) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
        return True

    def innovation_ok(self, x_c: float, y_c: float, confidence: float) -> bool:
        """Whether `update` would accept this centre (the filter started and inside the gate)."""
        if self.x is None:
            return True
        H = np.array([1.0, x_c - self.x_ref])
        S = H @ self.P @ H + self.c.sigma_meas**2 / max(confidence, 0.05)
        nu = y_c - H @ self.x
        return bool(nu * nu <= self.c.gate**2 * S)

    def update(self, x_c: float, y_c: float, confidence: float, width: float = math.nan) -> bool:
        """Fuse one bead centre (its width for `start_width_mm`); False if gated out (the
        filter may restart) or, cold, refused as a start (`cslx.runtime.filter_start`)."""
        c = self.c
        done = filter_start.step(self, x_c, y_c, confidence, width)
        if done is not None:
            return done
        H = np.array([1.0, x_c - self.x_ref])
        R = c.sigma_meas**2 / max(confidence, 0.05)
        S = H @ self.P @ H + R
        nu = y_c - H @ self.x
        if nu * nu > c.gate**2 * S:
            self.rejected += 1
            self.pending.append(np.array([x_c, y_c], float))
            return self._reacquire()
        K = self.P @ H / S
        self.x = self.x + K * nu
        self.P = (np.eye(2) - np.outer(K, H)) @ self.P
        self.P = 0.5 * (self.P + self.P.T)
        self.rejected = 0
        self.pending = []
        return True


def width_weight(width: float, widths, tol: float) -> float:
    """Weight of a bead of this width against the recent accepted ones (`KalmanConfig`
    `width_tol`): 1 within tol · m of their median m (or with fewer than 5 of them),
    else 1 / u², u = (width − m) / (tol · m)."""
    if len(widths) < 5 or not math.isfinite(width):
        return 1.0
    m = statistics.median(widths)  # exact as np.median, ≈ 2 µs against 66 on a deque of 20
    u = (width - m) / (tol * m)
    return 1.0 if abs(u) <= 1.0 else 1.0 / (u * u)


def offset_at_stripe(e: float, tan_theta: float, x_ref: float, wall) -> float:
    """y_r of the weld line y_r = e + tan θ (x_r − x_ref) where the horizontal stripe crosses
    it on the wall (docs/contracts.md, `offset_mm`): the stripe is laser plane 0 at z_r = 0,
    the line ``wall`` = (a, b, c), a x_r + b y_r + c = 0. On a rig whose stripe runs straight
    across (b = 0, the default) that x_r is x_ref and the offset is e; with the projector
    rolled it is not (15° / 25°: 8–21 mm further on, `experiments/tracking_generality.py`)."""
    a, b, c = wall
    den = a + b * tan_theta
    if not abs(den) > 1e-12 * (abs(a) + abs(b)):
        return float(e)
    x = (-c - b * (e - tan_theta * x_ref)) / den
    return float(e + tan_theta * (x - x_ref))


def stripe_x_on_axis(wall, default: float) -> float:
    """x_r where the horizontal stripe crosses the robot's axis (y_r = 0) on the wall: the
    line ``wall`` = (a, b, c) of `offset_at_stripe` at y_r = 0, x_r = −c / a; ``default``
    where the stripe runs along the axis (a = 0). The controller's look-ahead
    (`ControllerConfig.lookahead_mm`): the lever of a rotation on the offset the tracker
    reports. On the default rig it is x_ref (150 mm); with the projector rolled 8 / 15 / 25°
    155.3 / 159.9 / 167.0 mm against x_ref 150 (`experiments/tracking_generality.py`'s rigs)."""
    a, _, c = wall
    return float(-c / a) if abs(a) > 1e-12 else float(default)


def fit_line(x: np.ndarray, y: np.ndarray) -> tuple[float, float]:
    """(y0, m) of the least-squares line y = y0 + m x: `np.polyfit(x, y, 1)` in closed form
    (the normal equations about the means; within 1e-12 of it, ≈ 10 µs against ≈ 60 µs)."""
    xm, ym = float(np.mean(x)), float(np.mean(y))
    dx = x - xm
    m = float(dx @ (y - ym)) / float(dx @ dx)
    return ym - m * xm, m


def robust_line(
    x: np.ndarray,
    y: np.ndarray,
    w: np.ndarray,
    x_ref: float,
    floor: float,
    c: float,
    n_iter=8,
    c_refine: float = 0.0,
) -> tuple[float, float, float]:
    """Line y = e + tan θ · (x − x_ref) through weighted points, Tukey-biweight IRLS.

    Args:
        x, y: (n,) points, mm. w: (n,) prior weights (> 0; e.g. the bead confidence).
        x_ref: where the offset e is taken. floor: lower bound of the residual scale, mm.
        c: the biweight's cut-off in scales (a residual beyond c·scale has weight 0).
        c_refine: > 0: after the ``n_iter`` iterations at ``c``, ``n_iter`` more at this
            cut-off, from the line those found (`KalmanConfig.heading_tukey_refine`).
    Returns:
        (e mm, θ rad, standard deviation of θ rad); NaNs if fewer than 3 points keep weight.
    The scale is 1.4826 × the weighted median absolute residual (at least `floor`), re-estimated
    each iteration from the current line.
    """
    x = np.asarray(x, float) - x_ref
    y = np.asarray(y, float)
    w0 = np.asarray(w, float)
    u = w0.copy()
    nan = (math.nan, math.nan, math.nan)
    for it in range(2 * n_iter if c_refine > 0 else n_iter):
        sw = u.sum()
        if np.count_nonzero(u > 0) < 3 or sw <= 0:
            return nan
        xm, ym = (u @ x) / sw, (u @ y) / sw
        sxx = u @ (x - xm) ** 2
        if sxx <= 1e-9 * sw:
            return nan
        b = (u @ ((x - xm) * (y - ym))) / sxx
        a = ym - b * xm
        r = y - a - b * x
        order = np.argsort(np.abs(r))
        cw = np.cumsum(w0[order])
        mad = np.abs(r)[order][np.searchsorted(cw, 0.5 * cw[-1])]
        s = max(1.4826 * mad, floor)
        z = r / ((c_refine if it >= n_iter else c) * s)
        u = w0 * np.where(np.abs(z) < 1.0, (1.0 - z * z) ** 2, 0.0)
    kept = u > 0
    n_k = int(np.count_nonzero(kept))
    if n_k < 3:
        return nan
    un = u / u[kept].mean()  # weights of mean 1 over the kept points
    xm = (un @ x) / un.sum()
    sxx = un @ (x - xm) ** 2
    var = max((un @ r**2) / max(n_k - 2, 1), floor**2)
    return float(a), float(math.atan(b)), float(math.sqrt(var / max(sxx, 1e-12)))
