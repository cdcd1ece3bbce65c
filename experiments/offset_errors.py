"""Where the tracker's offset error comes from on the rendered T approaches (issue 12).

For each (seed, placement, nuisance) of `experiments.tracking_sequences` it runs the default
tracker and compares, frame by frame, this frame's bead measurement (its centre against the
true weld line at the same x_r, ``e_meas``) with the filtered offset's error (``e_off``):

- per run: the filter's offset mean / max and the frame of the max; the measurement's mean
  (a per-run bias), standard deviation, lag-1 autocorrelation (a slowly varying bias shows
  as a positive one) and the share of its sum of squares from frames beyond two robust
  standard deviations (outlier frames);
- per run and nuisance: what the nuisance adds to the measurement in the same frame
  (``e_meas`` minus the clean pass's, whose frame has the same pose and laser speckle:
  `render_image` seeds the speckle by seed and frame only), its mean and sd;
- per frame of the sun / glare / shadow passes: the longest stretch of the bead (within
  ±0.5 true widths of the true centre) without a profile point on each side, and the sign
  of the added error against the side of such a gap (≥ ``--gap-mm``).

    python -m experiments.offset_errors --seed 7301 [--also-seed 7302 ...] [--frames 48]

What it showed (dev seeds 7301, 7302, 7305, 1201–1206, both placements, every nuisance: 72
runs, default tracker at d977602; every run meets the offset goals but 7305 flank glare,
max 1.46 mm; 1205 flank sunny / glare give 8 / 14 false T frames and 81.8 % T recall):

- mostly not a per-run bias: the measurement's mean over a run, |mean| averaged per kind,
  clean 0.032, sunny 0.047 (largest 0.181), glare 0.040, shadow 0.019 mm, while its sd is
  0.15–0.98 mm; the errors are white (lag-1 autocorrelation median −0.06). On clean frames
  the ±0.2–0.7 mm is laser speckle: the same frame's error is nearly the same under every
  nuisance (7301 flank frames 4 / 5: −0.35 / +0.36 clean, −0.28 / +0.39 sunny, −0.29 /
  +0.37 glare, −0.36 / +0.39 shadow). What sun, glare or shadow add to the same frame is
  scatter (sd 0.02–1.05 mm per run) with a mean of −0.113 to +0.164 mm; the largest are sun
  in the beside placement (1206 +0.164, measurement mean +0.181; 7302 +0.100, +0.125), the
  pattern of the held-out misses (beside sunny).
- the filter's offset max is its first frames: in 31 of the first 48 runs (42 of 72) the
  run's largest |e_off| is on frames 0–2, where the filter has one to three beads (frame 0
  is the measurement itself: 7305 flank glare −1.43 mm, shadow −0.88). Frame 0 measured
  again with the bands set (a second and third pass), or frames 1 / 2 measured cold: the
  same numbers to 0.01 mm in all 48 runs, so not the cold start's processing.
- the sun's per-run bias: in 7 of the 9 beside sunny passes the + flank (the sunlit one in
  these renders) has a ≥ 2 mm stretch without points on 39–46 of the 48 frames (median
  3.0–3.5 mm; 1203 / 1204: 7 / 1 frames, offset mean 0.085 / 0.061 mm); the added error's
  mean over those frames is most of the run's bias, its sign set by the scene, not by the
  gap's side: 1206 +0.188, 7302 +0.121, 7305 −0.104, 1201 −0.070, 1202 +0.058, 1205 −0.036,
  7301 +0.001 mm (flank sunny: −0.178 to +0.081).
- where the added scatter comes from: a stretch of ≥ 2 mm of the bead (within ±½ true
  width of the true centre) without a profile point (the sunlit flank's clipped plateau,
  `experiments.tracking_diagnostics`). Added error, gap on the + side: RMS 0.470 mm (669
  frames), on the − side 0.254 (206), no gap 0.235 (1665); but no direction: mean −0.015 /
  −0.026 / −0.002 mm, towards the gap in 483 frames, away in 392. Frame by frame (1206
  beside sunny frames 10, 20, 21, 28, 41, 43: added +0.6 to +0.9 mm and −1.1) the points at
  the gap's two edges lie 0.3–1.1 mm too high (z +2.1 / +2.4 mm at +3.4 mm where the clean
  frame has +1.1 / +1.3) and the cap widens (18.3–19.5 mm for 16.3).

Tried, each variant against the default in one process (`experiments.tracking_diagnostics
--variant`), first on the 48 runs of 7301, 7302, 7305, 1201–1203, per kind offset mean /
max averaged over the runs / worst max mm (default clean 0.083 / 0.375 / 0.69, sunny
0.107 / 0.422 / 0.86, glare 0.100 / 0.447 / 1.46, shadow 0.091 / 0.445 / 0.90; heading
unchanged by the filter variants); none kept, and their code is not in the tree (options of
`KalmanConfig`, `WeldFeature` and `PipelineConfig` on the track12i branch's scratch tree):

- the Kalman measurement variance σ² / conf^p instead of σ² / conf (the confidence hardly
  ranks the error: RMS error 0.32–0.33 mm in every confidence bin 0.2–0.8): p = 0.5 sunny
  0.110 / 0.441, p = 0 0.119 / 0.463; offset-mean misses 0 → 1 / 2. An innovation-based
  noise scale (running mean of (ν² − HPHᵀ) / R, weight 0.05–0.1): floored at 1 no change
  (the model variance already exceeds the errors': RMS z 0.60), floored at 0.25 every kind
  worse (sunny 0.131 / 0.489). q_offset 0.08 → 0.04: means −0.002 to −0.007 but 7305 beside
  shadow 0.192 → 0.205 and 1201 flank glare 0.186 → 0.205 mm (two misses). Huber weights
  on the innovation, k = 1 / 1.5 model sd: sunny 0.107 → 0.099 / 0.102 (runs better 14 /
  worse 5 at k 1), but 1205 flank sunny 0.177 → 0.214 / 0.189 (a new miss at k 1).
- the cap fit's own position sd (its Gauss–Newton covariance, exported per frame; median
  0.06 mm, 4× below the errors but ranking them: RMS error 0.22 mm below the median sd,
  0.45–0.72 mm in its top 10 %; Spearman 0.28, sunny 0.35) as the variance × max(1,
  (sd / 0.06)²): max sunny 0.422 → 0.407, glare 0.447 → 0.436, shadow 0.445 → 0.416, but
  sunny mean 0.107 → 0.113 (7302 beside / flank sunny 0.113 / 0.111 → 0.196 / 0.177: in a
  narrow bead's sun the sd does not tell the bad frames, frame 2 +0.94 mm at sd 0.079,
  frame 3 −0.58 at 0.215); on 1204–1206 sunny 0.125 → 0.138, two offset-mean misses.
- all 72 runs (default clean 0.082 / 0.379 / 0.70, sunny 0.113 / 0.419 / 0.86, glare
  0.097 / 0.401 / 1.46, shadow 0.089 / 0.427 / 0.90; heading mean averaged over runs
  0.154 / 0.210 / 0.177 / 0.174°): the points within 6 columns (≈ 1.5 mm) of an interior
  gap of ≥ 4 columns weighted 0.1 / 0 in the bead's fits: sunny 0.131 / 0.133 mean, glare
  0.103 / 0.109, heading misses 0 → 3, offset mean better in 13 runs and worse in 29 (1206
  beside sunny itself 0.149 → 0.173): the edge points are too high but they are the
  sunlit flank's only evidence; 12 columns at 0.1 / 0.4: sunny 0.142 / 0.120, offset-mean
  misses 3 / 1; 4 columns at 0.4: every kind within 0.001 mm of the default's mean, max
  averaged 0.401–0.427 → 0.389–0.409 mm, but runs better 14 / worse 17, and the beside
  sunny runs worse (1206 0.149 → 0.183, 1205 0.172 → 0.184, 7301 0.103 → 0.131 mm). The
  confidence × (g_ref / g)² for a bead with a g mm gap
  (g_ref 1.5 / 2 / 3 mm; Kalman and heading window): sunny mean 0.142 / 0.132 / 0.120,
  offset-mean misses 5 / 4 / 1, heading misses 2 / 3 / 0. Fewer or lighter beads make the
  sunny estimate worse, not better: its error is not the white scatter a lower gain
  averages out.

Flank sunny against the other kinds (issue 12, track12n; dev seeds 1201–1206, 7301, 7302,
7320–7322, 7326, 7327 and fresh 7330–7335, default tracker at 3036b8e; per-frame records
of `tracking_diagnostics.replay`, re-fits of the stored profiles with `process_frame`):

- on the dev seeds flank sunny is not worse than beside sunny: offset mean averaged over
  13 flank sunny runs 0.102 mm, 11 beside sunny 0.106; flank clean is not much better
  (1201 / 1205 / 1206 / 7320 / 7321 clean 0.102 / 0.080 / 0.121 / 0.131 / 0.080, sunny
  0.139 / 0.126 / 0.100 / 0.144 / 0.149 mm). What sun adds is the bead measurement's
  scatter (sd per run 0.15–0.54 mm sunny, 0.21–0.30 clean) and, in some runs, a bias: 1201
  flank sunny measurement mean +0.143 mm (offset mean 0.139); fresh 7330 flank sunny
  (offset mean / max 0.187 / 0.621 mm, heading 0.435°) +0.17 mm over frames 25–47, while
  the vertical stripe crossed 10–14 mm beside the bead, on the plate: not the crossing.
- the crossing on the bead does move the horizontal profile in sun (height against the true
  cap, points within ±½ width, binned by y − the vertical stripe's y, 25 flank runs): sunny
  −0.15 to −0.37 mm mean (|r| 0.25–0.63) from −5 to −1 mm and +0.32 / +0.20 at 0 / +1 mm;
  shadow −0.11 / −0.15 at −2 / −1; clean within ±0.08 mm. Weighting those points down in
  the bead's fits (offline re-fit of the 25 runs; per-frame sd averaged over runs, and the
  mean |EMA(0.2)| of the error as a stand-in for the filter): default 0.333 / 0.094 mm;
  [−2, 2] mm weight 0 0.348 / 0.102; [−5, 1] at 0.1 0.428 / 0.101, at 0 0.491 / 0.121;
  [−3, 1] at 0.1 0.338 / 0.091. No gain (as track12e's ±2 mm).
- the bead's shape remembered (tried, code not kept): its cap half-chord and height as the
  median of the last 10 frames' free cap fits, and only the centre fitted with that shape
  (Tukey, plate included). The per-frame scatter falls (offline sd 1205 flank sunny 0.476
  → 0.343, 7302 flank sunny 0.470 → 0.362, 7320 beside sunny 0.612 → 0.307 mm) but where a
  flank is lost the shape's error becomes a constant shift towards it (the median free fit
  is 0.1–0.6 mm wider than the bead in sun): mean |EMA| 1201 beside sunny 0.095 → 0.177,
  1206 beside sunny 0.167 → 0.205, 7321 flank sunny 0.129 → 0.161, 7302 flank shadow 0.126
  → 0.179 mm; a soft prior (λ 1–300) the same. In the tracker (shape memory 10): 1205 flank
  sunny offset mean 0.126 → 0.082, but 7302 flank sunny 0.129 → 0.190 mm and heading 0.502
  → 0.663°; remembering only beads of confidence ≥ 0.45: 1205 0.273, 7320 0.232 mm. With
  the true shape (oracle) 7302 flank sunny sd 0.307 mm, mean −0.01: the shape estimate is
  the open step, and a per-run bias costs the offset mean more than scatter does.
- the tracker's width factor (`KalmanConfig.width_tol`) on the cap model's width instead of
  the circle's chord (the cap width's departure from its median ranks the bead error a
  little better: Spearman 0.25 against 0.23, confidence 0.16; RMS error 0.28 mm below 3 %
  departure, 0.50 at 10–20 %, 0.95 above 20 %). 29 dev runs (13 flank sunny, 6 beside
  sunny, 4 flank shadow, 4 flank glare, 2 flank clean), offset mean / max averaged, heading
  mean: flank sunny 0.102 / 0.457 / 0.178 → 0.099 / 0.459 / 0.162, beside sunny 0.136 →
  0.134, glare 0.092 → 0.095 mm, clean and shadow within 0.001 mm; heading misses 1 → 0
  (7302 flank sunny 0.502 → 0.48°); 5 runs better, 2 worse. Fresh 7330–7335 flank sunny:
  0.134 / 0.442 / 0.186 → 0.132 / 0.446 / 0.184, its worst run 7330 0.187 → 0.193 mm.
  A soft factor 1 / (1 + u²) at tolerance 0.15: dev flank sunny 0.097, fresh 0.126, but
  7330 0.210 mm and 0.52° (two new misses); the circle at tolerance 0.1: 0.104. Within
  the runs' scatter: not adopted.
- the bead's centre from its toes (`WeldConfig.centre` "toes") or the mean of toes and cap,
  offline re-fit of the same 29 runs (per-frame sd, |mean|, mean |EMA| averaged over the
  runs): cap 0.353 / 0.043 / 0.104, toes 0.536 / 0.078 / 0.161, mean 0.391 / 0.056 / 0.119
  mm. Beside sunny the mean does better (mean |EMA| 7320 0.193 → 0.130, 7322 0.135 →
  0.109, 1205 0.167 → 0.150, 1201 0.095 → 0.082; 1206 0.167 → 0.173) but flank runs much
  worse, also where the crossing is off the bead (7326 flank sunny 0.036 → 0.068, 7327
  0.063 → 0.161): in the flank placement the bead lies ≈ 35 mm further to the side of the
  camera's view and its toes are measured worse, crossing or not. Not adopted.
"""

from __future__ import annotations

import math
import pathlib

import numpy as np

from experiments.common import parser
from experiments.tracking_sequences import NUISANCES, PLACEMENTS, make_sequence, score


def run(tracker, seq: dict) -> dict[str, np.ndarray]:
    """Per frame: e_meas, e_off, confidence, and the bead's longest point-free stretch (mm)
    on each side of the true centre (within half the true width)."""
    from experiments.tracking_diagnostics import replay

    w0 = float(seq["sizes"][0])
    rows, obs = [], []
    for i, o, seen in replay(tracker, seq):
        obs.append(o)
        r = o.raw
        th = math.radians(seq["heading_deg"][i])
        yt = seq["offset_mm"][i] + math.tan(th) * (r["h_x_mm"] - seq["stripe_x_mm"][i])
        y = np.sort(seen["points_h"][:, 1][np.isfinite(seen["points_h"][:, 1])]) - yt
        gaps = []
        for lo, hi in ((-0.5 * w0, 0.0), (0.0, 0.5 * w0)):
            inside = np.concatenate([[lo], y[(y > lo) & (y < hi)], [hi]])
            gaps.append(float(np.max(np.diff(inside))))
        rows.append((r["h_y_mm"] - yt, o.offset_mm - seq["offset_mm"][i], r["h_confidence"], *gaps))
    a = np.array(rows)
    keys = ("e_meas", "e_off", "conf", "gap_minus", "gap_plus")
    return {**dict(zip(keys, a.T, strict=True)), "score": score(obs, seq)}


def summary(d: dict) -> str:
    """The per-run measures of the module docstring."""
    e, off = d["e_meas"], d["e_off"]
    m = np.isfinite(e)
    x = np.where(m, e - np.nanmean(e), 0.0)
    lag1 = float(x[1:] @ x[:-1] / max(x @ x, 1e-12))
    dev = e[m] - np.median(e[m])
    rs = 1.4826 * np.median(np.abs(dev))
    tail = float(np.sum(dev[np.abs(dev) > 2 * rs] ** 2) / max(np.sum(dev**2), 1e-12))
    s = d["score"]
    return (
        f"offset mean {s['offset_mean_mm']:.3f} max {s['offset_max_mm']:.3f} "
        f"(frame {int(np.nanargmax(np.abs(off)))}) | meas mean {np.nanmean(e):+.3f} "
        f"sd {np.nanstd(e):.3f} lag1 {lag1:+.2f} tail share {tail:.2f}"
    )


def main() -> None:
    p = parser(__doc__.splitlines()[0], 48, 7301)
    p.add_argument("--also-seed", type=int, action="append", default=[], help="(repeatable)")
    p.add_argument("--cache", default="/tmp/cslx-tracking-sequences/sequences")
    p.add_argument("--gap-mm", type=float, default=2.0, help="a flank gap at least this long")
    a = p.parse_args()
    from cslx.environment import configure

    configure()
    from cslx.runtime import Tracker
    from cslx.sensor import default_sensor

    tracker = Tracker.from_calibration(default_sensor(), log=lambda s: None)
    side = {"agree": 0, "against": 0, "added_plus": [], "added_minus": [], "none": []}
    for seed in (a.seed, *a.also_seed):
        for pl in PLACEMENTS:
            runs = {}
            for nu in NUISANCES:
                frames = 12 if a.quick else a.frames
                seq = make_sequence(seed, nu, pl, frames, pathlib.Path(a.cache))
                runs[nu] = d = run(tracker, seq)
                line = f"{seed} {pl} {nu}: {summary(d)}"
                if nu != "clean":
                    add = d["e_meas"] - runs["clean"]["e_meas"]
                    line += f" | added mean {np.nanmean(add):+.3f} sd {np.nanstd(add):.3f}"
                    plus, minus = d["gap_plus"] >= a.gap_mm, d["gap_minus"] >= a.gap_mm
                    one = plus ^ minus
                    ok = np.isfinite(add)
                    g = np.nanmean(add[one & ok]) if np.any(one & ok) else np.nan
                    line += f" | gap frames {int(np.sum(one))}, added mean there {g:+.3f}"
                    sign = np.sign(add[one & ok]) == np.where(plus, 1, -1)[one & ok]
                    side["agree"] += int(sign.sum())
                    side["against"] += int((~sign).sum())
                    side["added_plus"] += list(add[plus & ~minus & ok])
                    side["added_minus"] += list(add[minus & ~plus & ok])
                    side["none"] += list(add[~plus & ~minus & ok])
                print(line, flush=True)

    def stats(v):
        v = np.asarray(v or [np.nan])
        return f"mean {np.mean(v):+.3f} RMS {np.sqrt(np.mean(v * v)):.3f} mm ({v.size} frames)"

    print(
        f"frames with a flank gap >= {a.gap_mm} mm on one side: the added error towards it in "
        f"{side['agree']}, away in {side['against']}; added error with the gap on the + side "
        f"{stats(side['added_plus'])}, on the − side {stats(side['added_minus'])}, no gap "
        f"{stats(side['none'])}"
    )


if __name__ == "__main__":
    main()
