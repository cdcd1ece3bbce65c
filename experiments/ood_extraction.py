"""Generality audit of the default extractor (issue 11): conditions no one tuned for.

`experiments.robust_extraction` scores 18 conditions that all share the renderer's default
rig (Table 4's 640×480 camera, the cross of `cslx.sensor.default_sensor`) and a handful of
`cslx.sim.HARD_NUISANCES`. This script renders what that benchmark does not cover, with the
renderer's existing knobs only, and scores `cslx extract`'s default (method "linked", no
options) on it:

- other cameras and rigs: 1280×720 (Table 4's intrinsics scaled ×2, principal point in the
  middle), a short wide-angle lens (f ≈ 500 px, stronger barrel distortion: the stripe is
  ≈ 2 px wide), a rig 300 mm from the wall with a 120 mm baseline;
- the cross projector turned about the camera's axis by 20° and 35° (`cross_projector_planes`'s
  `roll_deg`, its offset turned with it: both stripes tilted from the image axes, the
  35° horizontal stripe from the top to the bottom of the frame, the vertical one leaving
  it at the right border), and aimed near the image's corner
  (the crossing ≈ 40 px from the border, part of the vertical stripe out of frame);
- green and blue lasers under glare and hard shadow, a saturated green core;
- a very thin faint stripe (sheet FWHM 0.3 mm, ≈ 1–2 px) over printed chessboards of 4 and
  10 mm squares;
- strong vignetting with a dark gain, and a bright scene (ambient light near the clip);
- saturated cores (with and without sun) through 8-bit JPEG at quality 70 / 85 / 95
  (OpenCV, 4:2:0 chroma subsampling);
- motion blur: the mean of 5 renders with the robot moved −3 … +3 mm along a straight weld
  (the surface is invariant along it, so the truth of the middle pose is exact; speckle and
  noise are drawn per sub-frame, so they average down as in a real exposure).

Frames alternate straight welds (even index) and T-junctions (odd), world and pose from
`default_rng([seed, i])` as `experiments.common.frame_at` draws them; seed = `--seed` (7400)
+ condition index. The seeds are fresh: no other experiment uses 7400–7499.

Metrics (docs/metrics.md, true calibration of each rig): detection rate over ground-truth
columns / rows, gross (> 1 mm) share of the matched centres, median and 95th percentile of
the 3-D error (mm), median pixel error, false positives (centres where the truth has no
stripe); a frame whose extraction raises is counted as a crash with its message.

Writes `ood_extraction.csv` and `ood_extraction.md` in `--out`.

First audit (issue 11, at `9911dcd`, 2 frames per condition): 1280×720, the wide lens, the
far rig, the corner crossing, green and blue lasers, vignetting, the bright scene, motion
blur and JPEG q95 all at 100 % detection and 0 % gross (the thin wide-lens vertical stripe
0.10 % gross). What fails: the cross turned by 35° (sunny: the crossing stripe on one side
of each column's profile pulls the centre 0.7–1.4 px towards it, and where a stripe leaves
the frame sideways the path follows a false ridge along the border, ≈ 16 false centres a
frame); JPEG q85 saturated + sun, vertical stripe 47 % detection (on one frame the kurtosis
search picks (1, −2, 1), the path is poor, 0.37 px median, and the no-stripe test's fixed
0.4 px limit on the median σ drops the whole stripe; R − G, R or 2R − G − B give
0.045–0.048 px on that frame); a thin faint stripe over 10 mm printed squares, vertical
50 % (one frame missed, not diagnosed); JPEG q70 + sun, horizontal 0.39 % gross.

The two whole-stripe drops, diagnosed and fixed (issue 11, branch drop11q; detection %,
gross %, median / p95 mm, 2 frames at seed 7400 unless said):
- JPEG q85 saturated + sun: JPEG leaves the clipped core at R 251–255, so only some of its
  pixels reach the clip level and the others, near-white with smeared G and B, decided
  the space. The colour search now also ignores pixels with a channel ≥ 240
  (`cslx.segmentation.search.SEARCH_CLIP_LEVEL`; the 72 development searches keep their
  spaces). V 47.29, 1.10, 0.176 / 0.308 → 99.69, 0.00, 0.052 / 0.243; H 99.69, 0.71,
  0.066 / 0.292 → 99.69, 0.94, 0.063 / 0.339. Held out (seed 7460, i.e. 7479, 4 frames):
  V 73.02, 0.00, 0.068 / 0.295 → 98.02, 0.69, 0.064 / 0.291 (one frame's stripe, dropped
  at σ 0.60 px, now found at σ 0.12 px, 13 gross centres where it had 31 ungated); H
  100, 0.00, 0.074 / 0.308 → 99.96, 0.43, 0.066 / 0.331 (11 gross centres on one frame in
  its new space). JPEG q95 saturated (its space changed too): H 0.059 / 0.186 → 0.044 /
  0.140, V 0.086 / 0.263 → 0.032 / 0.190, 100 % and no gross either way. JPEG q70 sunny H
  (one frame's space changed) 0.063 / 0.290 → 0.067 / 0.262; the bright scene V 0.0285 /
  0.131 → 0.0274 / 0.133; corner/clean H 0.0258 / 0.087 → 0.0272 / 0.088 (one frame).
- Thin stripe over 10 mm squares: the path was right (every row, 0.060 px median error,
  median σ 0.199 px) but its median ridge strength z 15.9 fell below the no-stripe test's
  18 (the first stage to drop it; colour search, candidates and path were fine). The test
  now keeps a faint stripe whose path is precise and long (σ ≤ 0.3 px, z ≥ 12, over half
  the rows; `cslx.segmentation.presence`, where the laser-off evidence is): V 50.00, 0.00,
  0.080 / 0.441 → 100.00, 0.00, 0.074 / 0.401. Held out (seed 7460, i.e. 7474, 4 frames): V 50.00,
  1.46, 0.084 / 0.632 → 75.00, 1.25, 0.087 / 0.611 — one frame rescued (z 17.7, σ 0.155),
  one still dropped (σ 0.342 px, z 13.4: its path is poor, 0.142 px median, and laser-off
  stripes reach σ 0.45 at z 15), H unchanged (100 %, z 18.7–23.3, close to the limit).

The turned cross, fixed (`cslx.segmentation.crossing`, branch turn11q): the other stripe is
found as a straight line across a band along the path (a Radon transform of the band's
ridges, both sides required), and the centres within its reach are interpolated where its
slope says the cross is turned ≥ 15°; centres within 1.5 px of the border across the stripe
are dropped and those within 1 σ_t of it interpolated. Condition: H / V detection %, gross %
(count), median / p95 mm, false positives, before → after. Seed 7400 (2 frames, used in
development): roll35/sunny H 98.42 → 97.81, 1.61 (18) → 0.54 (6), 0.048 / 0.491 → 0.047 /
0.290, fp 38 → 23; V 100 → 97.82, 3.44 (30) → 0, 0.054 / 0.710 → 0.044 / 0.131, fp 33 → 0;
roll35/saturated H 97.54 → 98.22, 0.61 (7) → 0.60 (7), 0.036 / 0.243 → 0.036 / 0.271;
V 98.16 → 97.40, 1.88 (17) → 0, 0.056 / 0.265 → 0.054 / 0.192, fp 22 → 0; roll20/clean H
median / p95 0.028 / 0.113 → 0.031 / 0.106, V 0.023 / 0.089 → 0.023 / 0.090. Every other
audit condition at 7400 (corner clean and glare, JPEG q70 / q85 / q95 saturated, q70 sunny,
thin stripe over 4 and 10 mm print, wide lens): identical. Held out (seed 7480 + condition,
4 frames, run once at the end): roll35/sunny H 49.28 → 48.53 (the H stripe missed on whole
frames before and after: not this fix), 3.73 (42) → 1.35 (15), 0.053 / 0.733 → 0.041 /
0.320, fp 53 → 21; V 99.89 → 97.98, 2.36 (42) → 0, 0.046 / 0.473 → 0.031 / 0.203, fp 64 → 0;
roll35/saturated H 99.30 → 98.02, 2.48 (56) → 0.58 (13), 0.049 / 0.264 → 0.046 / 0.204,
fp 122 → 67; V 100 → 96.81, 3.99 (70) → 0, 0.041 / 0.314 → 0.038 / 0.177, fp 98 → 0;
roll20/clean H 0.022 / 0.115 → 0.022 / 0.112, V 0.030 / 0.122 → 0.026 / 0.101. The
detection lost is at the border: every centre dropped there was a gross (> 1 mm) centre
before on the held-out frames (142 of 142), 37 of 39 at 7400 (one 0.5–1 mm, one less).
What remains: the sunny H stripe's 6–15 gross centres lie at the fan's oblique end (the
path runs 10–15 columns past the stripe's end inside the frame), not at the crossing. The
development benchmark (`robust_extraction`'s conditions, seeds 7100–7117, frame 0, both
kinds, in one process with the audit frames before and after): every condition identical
but saturated_sunny straight H (median 0.0228 → 0.0207 mm); pooled H / V 100.00 / 99.92 %,
0 gross, 0.0283 / 0.0277 mm, p95 0.123 / 0.127, unchanged. Cost: 12–13 ms per frame and
stripe (`crossing`).
Tried, not kept: (1) the previous attempt (`general11p`): centres near a crossing found by
the image on a profile's two sides differing by > 0.4 × the peak with a sign change inside
the region — 35° sunny gross H 18 → 6, V 30 → 0, but JPEG q70 saturated V median 0.074 →
0.105 mm and the thin stripe over 10 mm squares V gross 0 → 0.62 % (JPEG smear and print
edges trigger the asymmetry); the geometric line leaves both identical. (2) Interpolating
centres within 2.5 σ_t of the border (as there): on a saturated stripe (σ_t 9 px) the
smoothing's fit was extrapolated over 30 rows, 1.5 px off (35° saturated V median 0.056 →
0.061, p95 0.265 → 0.355); 1 σ_t keeps the gain (V gross 17 → 0). (3) The reach 2.5 σ_t
instead of 4: 0.47 px left at 30° on the synthetic cross (the final fits through the biased
columns just outside). (4) Crossings down to |slope| 0.1 (the default rig's are 0–0.2,
their pull ≤ 0.08 px on the synthetic cross): development H medians moved by up to
±0.003 mm, but against a baseline run in another frame order (below), so inconclusive;
0.22 leaves the development benchmark as it was. A caution for A/B runs: a frame's centres
can depend on the frames the process extracted before it (development frame 7104 H: median
0.028 mm after frames 7100–7103, 0.035 mm alone — main's code — or after the audit's
frames; up to 0.24 px apart): compare variants on the same frame sequence.

The turned cross's whole-stripe drops and its oblique end, fixed (branch roll11r). Fresh seeds
7500–7515 (frames 0–1; not the held-out 7480–7499), the no-stripe test off: the horizontal
stripe was there on every frame (96–100 % of the columns, output median 0.03–0.07 px), and
the first stage to drop it was the no-stripe test (`cslx.segmentation.presence`): its σ
limit (0.4 px) met the first pass's σ of a turned stripe, 0.40–0.57 px at z 65–332 (the
first pass smooths along the image axis, so a turned stripe's column profile is smeared and
its path rough; the second pass, along the path, is what makes the output precise). The
test now keeps a strong stripe (median z ≥ 60, above every laser-off path's ≤ 49.9, σ ≤
1.5 px); evidence in `presence`. The tail: the first pass's smoothing along the axis leaves
a ridge for ≈ 2 σ_along past the fan's end that stays near the end's row, and the path
followed it (7502/0 H: columns 38–49 past the end at 50, 1.0–1.3 px off the stripe's line,
and columns 50–53 biased 2.9–1.6 px); `cslx.segmentation.ends` cuts a turned path's end
where two consecutive centres leave the line through the path further inside by > 1 px.
Before → after (presence tier alone / with the trim), one process, same frame order, H / V:
detection %, gross % (count), median / p95 mm, false positives, stripes dropped whole.
Fresh seeds 7516–7523, frames 0–1 (16 frames per condition): roll35/sunny H 91.55 → 97.53
/ 96.84, 0.57 (48) → 0.58 (52) / 0.19 (17), 0.036 / 0.236 → 0.037 / 0.237 / 0.035 / 0.218,
fp 184 → 193 / 0, dropped 1 → 0; roll35/clean (no nuisance) H 24.29 → 98.02 / 97.49, 0.31
(7) → 0.44 (40) / 0.03 (3), 0.031 / 0.166 → 0.034 / 0.193 / 0.029 / 0.172, fp 53 → 217 /
0, dropped 12 → 0; V 67.72 → 97.69, dropped 5 → 0, 0.029 / 0.181 → 0.028 / 0.174 (the
trim: no change); roll35/saturated H 97.96 → 97.83 (trim),
0.60 (54) → 0.27 (24), 0.039 / 0.194 → 0.035 / 0.180, fp 277 → 2; V unchanged; roll20/clean
unchanged (bit for bit). Pooled over the four, H 78.98 → 98.42 / 98.09 %, 109 → 146 / 44
gross, fp 568 → 741 / 56; V 90.73 → 98.10 %. Seed 7400 (2 frames): roll35/sunny H 97.81 →
96.93 %, 0.54 (6) → 0 gross, 0.047 / 0.290 → 0.044 / 0.230, fp 23 → 0; roll35/saturated H
98.22 → 98.14, 0.60 (7) → 0.26 (3), 0.036 / 0.271 → 0.031 / 0.251, fp 35 → 0; every other
frame and stripe of the audit at 7400 (124 of 128) bit-identical. Development benchmark
(`robust_extraction`'s 18 conditions, seeds 7100–7117, frame 0, both stripes, same process):
all 36 frame-stripes bit-identical (pooled H / V 100.00 / 99.92 %, 0 gross, 0.0283 /
0.0277 mm, p95 0.123 / 0.127). The detection lost to the trim (≈ 0.3–0.9 %) is the ≈ 5
columns inside the end whose first-pass profiles mix the missing part. Cost: the trim 0.6 ms
per stripe alone (640 columns, jit, dispatch included). Held out (seed 7480 + condition, 4
frames, run once at the end): roll35/sunny H 48.53 → 96.19 %, dropped 2 → 0 of 4, gross 1.35
(15) → 0.82 (18; two more frames scored), 0.041 / 0.320 → 0.044 / 0.305 mm, fp 21 → 0;
roll35/saturated H 98.02 → 97.80, 0.58 (13) → 0.18 (4), 0.046 / 0.205 → 0.045 / 0.208, fp
67 → 0; V unchanged on both (bit for bit). Not fixed: the cross turned 45°
(fresh 7500–7502, no-stripe test off: 88–97 % detection but 9–328 gross centres and 100–196
false positives a stripe, clean or sunny): beyond the crossing step's reach.

The cross turned 45° (conditions roll45/clean, /sunny, /saturated, added; branch cross45).
Diagnosed on fresh seeds 7700–7701 (frames 0–1): at 45° the stripes run at 46.5° and −50°
(slopes +1.05 and −1.19 rows per column), both within the path's free slope of 1 px per
column, so the path followed one stripe to the crossing and the other after it, or jumped
across a gap onto the other (p95 86–160 mm, 18–73 % gross). `cslx.segmentation.orient`
measures each stripe's direction (Hessian directions of the 4 × 4-block image, the peak
nearest the search axis), and where it is ≥ 25° from the axis the first pass smooths along
it and links the offsets from it; pieces of the path along the other stripe are dropped
(saturated V at 7700–7701: 46 gross → 0, false positives 440 → 0) and the path's ends cut
where the strength falls below half its plateau (smoothed along the stripe, the fan's end
is an erf ramp: 7701/0 clean H, 14 false centres past the end → 3). Every development
frame's stripe lies within 6.6° of its axis (seeds 7100–7117, frame 0), so none is
oriented: the development benchmark (18 conditions, both stripes, old and new on each frame
in one process) is bit-identical (pooled H / V 100.00 / 99.92 %, 0 gross, 0.0283 / 0.0277
mm, p95 0.123 / 0.127). Before → after, fresh seeds 7702–7703, frames 0–1 (4 frames per
condition), old and new on each frame in one process; detection %, gross % (count), median
/ p95 mm, false positives: roll45/clean H 92.57 → 98.99, 6.39 (105) → 0, 0.079 / 33.2 →
0.045 / 0.217, fp 366 → 2; V 92.69 → 98.45, 62.0 (778) → 0, 63.7 / 164 → 0.033 / 0.116,
fp 490 → 0; roll45/sunny H 92.85 → 98.87, 16.9 (279) → 0, 0.106 / 84.3 → 0.062 / 0.237,
fp 412 → 1; V 70.75 → 96.82, 35.3 (338) → 0, 0.141 / 165 → 0.049 / 0.137, fp 372 → 0;
roll45/saturated H 99.32 → 96.73, 20.2 (357) → 0.17 (3), 0.101 / 83.0 → 0.052 / 0.294, fp
429 → 3; V 98.23 → 95.35, 39.6 (526) → 0, 0.124 / 151 → 0.035 / 0.168, fp 522 → 0. The 35°
cross is oriented too: roll35/sunny H 97.37 → 98.97, 0.04 (1) → 0, 0.037 / 0.226 → 0.032 /
0.166, fp 0 → 2; V 97.85 → 98.57, 0.06 (1) → 0, 0.031 / 0.193 → 0.025 / 0.158;
roll35/saturated mixed: H 97.59 → 97.59, 0.13 (3) → 0.09 (2), 0.037 / 0.189 → 0.036 /
0.205, fp 0 → 8; V 96.96 → 95.97, 0 → 0.23 (4, one frame), 0.047 / 0.187 → 0.052 / 0.172.
roll20 (stripes at 13–20°) is not oriented: identical. The detection still lost at 45°
(1–5 %) is at the ends and the border. Cost (640×480, warm, load 0.7–1.6, one run, old and
new alternating): the direction 1.4–2.0 ms, the smoothing along 14–18 ms (37 taps with
interpolation across; computed once for both σ passes); whole frame and stripe, roll45 54–69
→ 70–103 ms, roll35/sunny 62 / 76 → 80 / 71 ms (H / V), the default rig (sunny, not
oriented) 50 / 46 → 53 / 53 ms. Held out (seed 7480 + condition, 4 frames, run once at the
end; the roll45 conditions' seeds 7503–7505 share frames 0–1's worlds and poses with the
earlier 35° development seeds 7500–7515, other rigs): roll45/clean H 93.95 → 98.30, 20.35
(338) → 0, 0.087 / 87.7 → 0.035 / 0.187, fp 432 → 2; V 92.69 → 98.36, 55.1 (685) → 0, 41.5
/ 156 → 0.025 / 0.127, fp 515 → 0; roll45/sunny H 93.00 → 98.81, 11.5 (190) → 0.34 (6),
0.071 / 72.0 → 0.045 / 0.211, fp 405 → 2; V 92.67 → 98.00, 38.9 (487) → 0, 0.162 / 153 →
0.021 / 0.248, fp 519 → 0; roll45/saturated H 98.02 → 96.61, 14.7 (255) → 0.12 (2), 0.074 /
75.0 → 0.035 / 0.228, fp 411 → 8; V 100 → 95.35, 75.3 (1021) → 0, 77.9 / 159 → 0.035 /
0.114, fp 511 → 0; roll35/sunny H 96.19 → 98.34, 0.82 (18) → 0, 0.044 / 0.305 → 0.039 /
0.190, fp 0 → 2; V 97.98 → 98.32, 0 → 0, 0.031 / 0.201 → 0.029 / 0.149; roll35/saturated H
97.80 → 97.41, 0.18 (4) → 0.05 (1), 0.045 / 0.208 → 0.044 / 0.201, fp 0 → 7; V 96.81 →
95.84, 0 → 0, 0.038 / 0.177 → 0.042 / 0.195 (worse); roll20/clean identical. Open: the
saturated 35° vertical stripe (its first pass at 29° from the axis) loses ≈ 1 % detection
and 0.004 mm median when oriented; a 45° saturated stripe's ends and border cost 3–5 %.

The turned cross at the border (branch cross45s, `cslx.segmentation.border`). Where the 45°
detection is lost (development seeds 7583–7585 = `--seed 7560`, frames 0–7, by region): 76–
100 % of the lost centres lie within 12 px of the border across (clean H 37 of 38, V 39 of 46;
sunny H 51 of 59, V 55 of 77; saturated H 102 of 121, V 119 of 124), the rest at the fans'
ends inside the frame (H 1–19), the border along (V 5–15) and clipped pixels (V 5–7); none at
the crossing. The cut profile and its mirror merge into one ridge on the border, so the
first pass has no candidate there. The ends that leave the frame across are now set by a
quadratic through the centres further inside, up to the border, while the image is lit.
Before → after, same process and frame order (detection %, gross count, false positives,
median / p95 mm), frames 0–7: roll45/clean (7583) H 98.93 → 99.92, 0 → 0, 2 → 2, 0.0369 /
0.199 → 0.0369 / 0.198; V 98.38 → 99.48, 2 → 2, 0 → 0, 0.0326 / 0.141 → 0.0330 / 0.144;
roll45/sunny (7584) H 98.33 → 99.83, 0 → 0, 2 → 2, 0.0408 / 0.228 → 0.0427 / 0.242; V 97.16
→ 98.75, 0 → 0, 0.0398 / 0.276 → 0.0399 / 0.283; roll45/saturated (7585) H 96.55 → 99.49, 0 →
2, 6 → 8, 0.0392 / 0.286 → 0.0405 / 0.312; V 95.35 → 99.81, 0 → 0, 0.0375 / 0.220 → 0.0380 /
0.228; roll20/clean (7575): identical; roll35/sunny (7576) H 98.92 → 99.76, 0 → 0, 0.0316 /
0.148 → 0.0319 / 0.160; V 98.40 → 99.78, 0 → 5, fp 0 → 2, 0.0267 / 0.140 → 0.0260 / 0.136;
roll35/saturated (7577) H 97.43 → 99.87, 5 → 5, fp 16 → 18, 0.0353 / 0.194 → 0.0355 / 0.204;
V 95.84 → 97.84, 5 → 11, fp 0 → 4, 0.0338 / 0.152 → 0.0343 / 0.174. Development benchmark
(18 conditions, seeds 7100–7117, frame 0, both stripes): all 36 frame-stripes bit-identical.
Held out (once, at the end: `--seed 7400`, roll45 seeds 7423–7425, frames 0–3): clean H 98.91
→ 99.83, 0 → 0, 0.0371 / 0.185 → 0.0370 / 0.196; V 98.48 → 99.85, 0 → 2, 0.0287 / 0.218 →
0.0278 / 0.216; sunny H 98.72 → 99.66, 0 → 0, fp 2 → 3, 0.0520 / 0.238 → 0.0526 / 0.237; V
94.69 → 97.96, 0 → 8, 0.0335 / 0.264 → 0.0353 / 0.297; saturated H 97.04 → 99.94, 0 → 0, fp
6 → 4, 0.0438 / 0.314 → 0.0467 / 0.337; V 95.41 → 99.85, 0 → 0, 0.0325 / 0.138 → 0.0356 /
0.156. Cost: `border.extend` 1.8–6.8 ms a stripe on host arrays (median, load ≈ 8; the images
come to the host only for a qualifying end, 0.1 ms). Tried: a straight line (clean V frames 3
and 7: 17 gross centres, the lens bends the stripe near the border); a quadratic without
the check against the path's own centres nearer the border (roll35/saturated V: 15–17 gross
a frame across a surface corner); `FIT_WIDTHS` 1.0 (the same). Open: the gross centres the
extension still adds on some frames (roll35 V, held-out sunny V), the extrapolation's
slightly higher errors (medians +0–0.003 mm), and the rest of the misses (fans' ends,
the border along, clipped pixels). Merged off (`cslx.segmentation.robust.BORDER`): the held-out
gross centres (0 → 2 clean V, 0 → 8 sunny V) break the gross goal that the 45° frames met
without it; detection there stays 94.7–98.9 % until the extension adds no gross centre.

The border extension's gross centres (branch border11b; `border.extend` replayed on the inputs
recorded from `extract` with `BORDER` on, so off and on score the same frames in one process).
Development: seeds 7576–7577 and 7583–7585 (frames 0–7), fresh 7800–7804 (frames 0–7) and
7806–7809 (saturated only, frames 0–7). The quadratic added 78 gross centres (summed over the
conditions); those examined (7 frame-stripes, 0.6–15 px from the border across) were one of:
(1) its curvature fitted the support's 0.1–0.3 px bias and was extrapolated 21–44 centres, the
line through the same support 0.02–0.4 px off; (2) the truth bends between the support and the
border (surface corners, T-junctions; 10 % of the 205 qualifying ends bend by ≥ 1.1 px) and
the quadratic passed the zone test there; (3), found with the line: a path ending at the
border along (its profiles whole), followed 60–70 px from the border across (7809/3 H). Now: a
line (`border.FIT_DEG` 1; the zone test rejects case 2 where the path's own centres show the
bend) and the fit must leave the frame across before its end along. Detection %, gross count,
median / p95 mm, off → quadratic → line (pooled 16 frames a condition, 32 for the saturated
ones): roll45/clean H 98.63 → 99.72 → 99.70, 0 → 0 → 0, 0.0357 / 0.188 → 0.0360 / 0.186 →
0.0354 / 0.186; V 98.42 → 99.52 → 99.39, 2 → 2 → 2, 0.0263 / 0.133 → 0.0267 / 0.141 → 0.0263 /
0.126; roll45/sunny H 98.52 → 99.86 → 99.83, 0 → 0 → 0; V 97.36 → 98.89 → 98.76, 2 → 2 → 2;
roll45/saturated H 96.77 → 99.67 → 99.54, 26 → 35 → 23; V 95.36 → 99.84 → 99.34, 2 → 21 → 16,
0.0373 / 0.215 → 0.0379 / 0.238 → 0.0378 / 0.214; roll35/sunny H 98.86 → 99.72 → 99.66, 0 → 0
→ 0; V 98.29 → 99.04 → 98.86, 1 → 7 → 0; roll35/saturated H 97.26 → 99.72 → 99.16, 11 → 11 →
11; V 95.88 → 98.53 → 98.50, 5 → 49 → 5. What the line still adds (14, all on 7808/3 V): the
truth bends ≈ 26 rows before the border (slope 0.82 → 0.67) and the path's own centres there
follow the line, not the bend (they are smoothed along the path), up to 1.1 px off before the
extension and up to 2.7 px after; the zone test cannot see that. Held out, once per set
(frames 0–3; detection %, gross count, median / p95 mm, off → quadratic → line):
- `--seed 7827` / `7847` (roll45 7850–7852, roll35 7853–7854), the final line with the
  along check: roll45/clean H 98.98 → 99.89 → 99.89, 0 → 0 → 0; V 98.36 → 99.78 → 99.41,
  0 → 5 → 0, 0.0349 / 0.153 → 0.0353 / 0.170 → 0.0349 / 0.147; roll45/sunny H 98.86 → 100.00
  → 99.83, 0 → 0 → 0; V 97.66 → 98.64 → 98.57, 322 → 322 → 322 (one frame's path on the wrong
  stripe, with or without the extension); roll45/saturated H 96.48 → 99.83 → 99.89, 2 → 0 →
  2; V 95.53 → 99.70 → 98.51, 0 → 7 → 8, 0.0373 / 0.123 → 0.0398 / 0.191 → 0.0384 / 0.143;
  roll35/sunny H 98.52 → 99.70 → 99.70, 6 → 6 → 6; V 98.09 → 99.33 → 99.38, 0 → 0 → 0;
  roll35/saturated H 97.11 → 99.87 → 99.70, 1 → 1 → 1; V 95.81 → 97.49 → 97.43, 0 → 21 → 22,
  0.0271 / 0.143 → 0.0280 / 0.203 → 0.0288 / 0.140 (the line before the along check
  differed only in roll35/saturated H 99.87 % and roll45/sunny V 98.72 %; this set was
  scored with it first, then the along check came from 7806–7809).
- `--seed 7837` / `7857` (roll45 7860–7862, roll35 7863–7864), the final line with the along
  check: roll45/clean H 98.58 → 99.43 → 99.38, 0 → 0 → 0; V 98.29 → 99.85 → 99.48, 0 → 0 →
  0, 0.0233 / 0.088 → 0.0234 / 0.092 → 0.0230 / 0.083; roll45/sunny H 98.59 → 99.49 → 99.77,
  0 → 0 → 0; V 97.72 → 99.93 → 99.78, 0 → 3 → 8, 0.0350 / 0.134 → 0.0344 / 0.152 → 0.0353 /
  0.162; roll45/saturated H 96.30 → 99.88 → 99.88, 7 → 7 → 7; V 95.08 → 99.77 → 99.69, 1 →
  1 → 2; roll35/sunny H 98.90 → 99.91 → 99.96, 0 → 0 → 0; V 98.29 → 99.89 → 99.43, 0 → 0 →
  0; roll35/saturated H 97.43 → 99.83 → 99.69, 0 → 0 → 0; V 95.66 → 99.72 → 98.70, 0 → 15 →
  0, 0.0357 / 0.161 → 0.0367 / 0.223 → 0.0357 / 0.172.
The line adds fewer gross centres than the quadratic (development 78 → 14, held out 33 → 30
and 18 → 9) but not none: the vertical stripe's ends (roll45/saturated, roll45/sunny,
roll35/saturated) still got 1–22 a condition. What was left needed the image, not the path:
the extension now ends where the stripe measured on the profiles along the border (whole
there; a half-maximum centroid per centre, 0.28 px median off where the line was right, so
averaged over 12 centres) leaves the line by > 1.5 px (`border.MEASURE_TOL`). Development
(same frames as above, off → line → line with the image check): gross roll45/saturated H 26
→ 23 → 18, V 2 → 16 → 0, detection V 95.36 → 99.34 → 99.08, H 96.77 → 99.54 → 99.40 %; every
other condition as with the line alone (roll45/clean, roll45/sunny, roll35/* identical). The
mask `extend` gets holds only the clipped pixels left unfilled (`robust._prepare`), not the
whole core, so a clipped band is no centre (its middle 3.5 px off). Held out on seeds never
looked at before, once: `--seed 7847` / `7867` (roll45 7870–7872, roll35 7873–7874), frames
0–3, off → quadratic → final (detection %, gross count, median / p95 mm): roll45/clean H
98.97 → 99.77 → 99.83, 0 → 0 → 0, 0.0475 / 0.209 → 0.0476 / 0.209 → 0.0480 / 0.209; V 97.91
→ 99.03 → 98.51, 0 → 1 → 0, 0.0213 / 0.119 → 0.0219 / 0.119 → 0.0212 / 0.111; roll45/sunny
H 98.52 → 99.83 → 99.83, 0 → 0 → 0, 0.0511 / 0.252 → 0.0519 / 0.260 → 0.0511 / 0.270; V
97.31 → 98.65 → 98.13, 0 → 0 → 0, 0.0339 / 0.217 → 0.0358 / 0.210 → 0.0337 / 0.206;
roll45/saturated H 96.79 → 100.00 → 99.71, 0 → 0 → 0, 0.0360 / 0.223 → 0.0355 / 0.265 →
0.0367 / 0.218; V 95.36 → 99.85 → 99.77, 0 → 0 → 0, 0.0429 / 0.206 → 0.0435 / 0.247 → 0.0444
/ 0.189; roll35/sunny H 99.26 → 100.00 → 99.96, 0 → 0 → 0, 0.0388 / 0.156 → 0.0395 / 0.157 →
0.0395 / 0.150; V 98.27 → 99.89 → 99.44, 0 → 5 → 0, 0.0335 / 0.194 → 0.0344 / 0.221 → 0.0331
/ 0.216; roll35/saturated H 96.68 → 99.91 → 98.66, 2 → 2 → 2, 0.0373 / 0.211 → 0.0378 / 0.225
→ 0.0366 / 0.226; V 95.82 → 99.51 → 98.74, 0 → 9 → 0, 0.0354 / 0.155 → 0.0366 / 0.214 →
0.0354 / 0.144 (`main` itself, `--seed 7847`, roll45/sunny and roll45/saturated, `BORDER` on:
the same figures, so the replay is the pipeline; the recorded outputs also equal the replayed
ones bit for bit on all 200 recorded frame-stripes checked). The final code on the two
earlier held-out sets (looked at before the image
check, so not clean): 7850–7854, gross added 0 (roll35/saturated V 95.81 → 95.98 %,
roll45/saturated V 95.53 → 96.05 %: the check ends most of those extensions; roll45/saturated
H 99.77 %; the other condition-stripes as the line's above); 7860–7864, 1 added
(roll45/saturated V 7862/3, 0.1 px from the border, 1.0 mm off; 1 → 2 gross, 99.69 %),
roll45/sunny V 99.12 % with 0 gross (the line's 8 gone), H 99.72 %, roll45/saturated H
99.48 %, the rest as the line's above. So `robust.BORDER` is on. Development benchmark
(`robust_extraction`'s 18 conditions, seeds 7100–7117, frame 0, both stripes): `extend`
returns its inputs unchanged on all 36 frame-stripes (no end qualifies), so bit-identical.

What the turned cross still lost after that, and the fixes (branch roll11: the extension to
the outer pixels' edge and through corners, a single direction peak of the other stripe):
`experiments/roll_losses.py`'s docstring.
"""

from __future__ import annotations

import dataclasses
import math
import os
import time
from collections.abc import Callable

import numpy as np

from experiments import common as C

__all__ = ["CONDITIONS", "Condition", "main", "render"]

FIELDS = [
    "condition",
    "stripe",
    "frames",
    "detection_rate",
    "gross_rate",
    "median_mm",
    "p95_mm",
    "median_px",
    "false_positives",
    "n_gt",
    "crashes",
]


@dataclasses.dataclass(frozen=True)
class Condition:
    """One audit condition: a rig, a nuisance (preset name and overrides) and a post-step."""

    rig: str = "default"
    nuisance: str = "clean"
    overrides: tuple[tuple[str, object], ...] = ()
    jpeg: int = 0  # JPEG quality; 0: PNG (no compression)
    motion_mm: float = 0.0  # robot travel during the exposure (straight welds only)
    kinds: tuple[str, ...] = C.KINDS


def _rig(name: str):
    """The sensor of a named rig (true calibration)."""
    from cslx.sensor import default_sensor
    from cslx.sensor.rig import (
        TABLE4_DIST,
        TABLE4_K,
        cross_projector_planes,
        default_mount,
        sensor_from_arrays,
    )

    origin, target = (-60.0, -60.0, 0.0), (40.0, 0.0, 230.0)
    K, dist, size, roll, mount = np.array(TABLE4_K), TABLE4_DIST, (640, 480), 0.0, {}
    if name == "default":
        return default_sensor()
    if name == "hd720":
        K = np.array([[2 * K[0, 0], 0, 640.0], [0, 2 * K[1, 1], 360.0], [0, 0, 1]])
        size = (1280, 720)
    elif name == "wide":
        K = np.array([[500.0, 0, 322.0], [0, 498.0, 236.0], [0, 0, 1]])
        dist = (-0.38, 0.16, 2e-4, -3e-4)
    elif name == "far":
        origin, target, mount = (-85.0, -85.0, 0.0), (40.0, 0.0, 300.0), dict(standoff_mm=300.0)
    elif name.startswith("roll"):
        # The whole projector turned about the camera's axis (its offset too), so the
        # triangulation angles stay the default rig's (≈ 1 mm per px along the search
        # axis); turning the sheets alone about a fixed offset puts the baseline almost in
        # sheet 0 at 35° (2.6 mm per px).
        roll = float(name[4:])
        c, s = math.cos(math.radians(roll)), math.sin(math.radians(roll))
        origin = (-60.0 * (c - s), -60.0 * (s + c), 0.0)
        target = (40.0 * c, 40.0 * s, 230.0)
    elif name == "corner":
        target = (68.0, -58.0, 230.0)
    else:
        raise ValueError(f"unknown rig {name!r}")
    planes = cross_projector_planes(origin=origin, target=target, roll_deg=roll)
    R_cr, T_cr = default_mount(**mount)
    return sensor_from_arrays(K, dist, planes, R_cr, T_cr, size)


#: The audit's conditions, by name.
CONDITIONS: dict[str, Condition] = {
    "hd720/clean": Condition("hd720"),
    "hd720/sunny": Condition("hd720", "sunny"),
    "wide/clean": Condition("wide"),
    "wide/sunny": Condition("wide", "sunny"),
    "far/shadow": Condition("far", "shadow"),
    "roll20/clean": Condition("roll20"),
    "roll35/sunny": Condition("roll35", "sunny"),
    "roll35/saturated": Condition("roll35", "saturated"),
    "corner/clean": Condition("corner"),
    "corner/glare": Condition("corner", "glare"),
    "green/glare": Condition(nuisance="glare", overrides=(("laser_rgb", (0.12, 1.0, 0.2)),)),
    "blue/shadow": Condition(nuisance="shadow", overrides=(("laser_rgb", (0.04, 0.18, 1.0)),)),
    "green/saturated": Condition(
        nuisance="saturated", overrides=(("laser_rgb", (0.12, 1.0, 0.2)),)
    ),
    "thin/printed4": Condition(
        nuisance="printed",
        overrides=(("sheet_fwhm_mm", 0.3), ("laser_power", 60.0), ("printed_mm", 4.0)),
    ),
    "thin/printed10": Condition(
        nuisance="printed",
        overrides=(("sheet_fwhm_mm", 0.3), ("laser_power", 60.0), ("printed_mm", 10.0)),
    ),
    "wide/thin": Condition("wide", overrides=(("sheet_fwhm_mm", 0.4), ("laser_power", 80.0))),
    "vignette/dark": Condition(
        overrides=(("vignetting", 3.0), ("ambient", 40.0), ("laser_power", 90.0))
    ),
    "bright": Condition(overrides=(("ambient", 330.0), ("laser_power", 200.0))),
    "jpeg70/saturated": Condition(nuisance="saturated", jpeg=70),
    "jpeg85/saturated_sunny": Condition(nuisance="saturated_sunny", jpeg=85),
    "jpeg95/saturated": Condition(nuisance="saturated", jpeg=95),
    "jpeg70/sunny": Condition(nuisance="sunny", jpeg=70),
    "motion/sunny": Condition(nuisance="sunny", motion_mm=6.0, kinds=("straight",)),
    "roll45/clean": Condition("roll45"),
    "roll45/sunny": Condition("roll45", "sunny"),
    "roll45/saturated": Condition("roll45", "saturated"),
}


def _nuisance(cond: Condition):
    from cslx import sim

    base = {**sim.NUISANCES, **sim.HARD_NUISANCES}[cond.nuisance]
    return base._replace(**dict(cond.overrides))


def _jpeg(image: np.ndarray, quality: int) -> np.ndarray:
    import cv2

    ok, buf = cv2.imencode(".jpg", np.ascontiguousarray(image[..., ::-1]),
                           [cv2.IMWRITE_JPEG_QUALITY, int(quality)])  # fmt: skip
    if not ok:
        raise RuntimeError("JPEG encoding failed")
    return np.ascontiguousarray(cv2.imdecode(buf, cv2.IMREAD_COLOR)[..., ::-1])


def render(cond: Condition, seed: int, index: int, sensor):
    """(image, gt) of frame `index` of one condition (see the module docstring)."""
    from cslx import sim

    kind = cond.kinds[index % len(cond.kinds)]
    rng = np.random.default_rng([seed, index])
    world = sim.random_world(kind, rng)
    pose = sim.random_pose(world, kind, rng, sensor)
    nz = _nuisance(cond)
    noise_seed = int(rng.integers(2**31))
    image, gt = sim.render_frame(sensor, world, pose, nz, seed=noise_seed)
    if cond.motion_mm:
        d = np.asarray(world.dirs, float)[0]
        frames = []
        for k, s in enumerate(np.linspace(-cond.motion_mm / 2, cond.motion_mm / 2, 5)):
            p = pose._replace(x=pose.x + s * d[0], y=pose.y + s * d[1])
            frames.append(
                sim.render_image(sensor, world, p, nz, seed=noise_seed + k, scene_seed=noise_seed)
            )
        image = np.clip(np.round(np.mean(frames, axis=0)), 0, 255).astype(np.uint8)
    if cond.jpeg:
        image = _jpeg(image, cond.jpeg)
    return image, gt


def _centres(image, stripe: str):
    from cslx import segmentation as seg

    return seg.centres_to_pixels(seg.extract(image, "linked", stripe=stripe), stripe)


def main(
    frames: int = 2,
    seed: int = 7400,
    out: str = str(C.RESULTS),
    only: tuple[str, ...] = (),
    centres: Callable = _centres,
) -> list[dict]:
    """Score every condition (or those named in `only`), both stripes; write the tables."""
    names = [n for n in CONDITIONS if not only or n in only]
    load_start = C.load_average()
    t0 = time.time()
    rows, sensors = [], {}
    for c, name in enumerate(CONDITIONS):
        if name not in names:
            continue
        cond = CONDITIONS[name]
        sensor = sensors.setdefault(cond.rig, _rig(cond.rig))
        pools = {s: C.Pool() for s in ("h", "v")}
        crashes = {s: [] for s in ("h", "v")}
        for i in range(frames):
            image, gt = render(cond, seed + c, i, sensor)
            for stripe in ("h", "v"):
                try:
                    uv = np.asarray(centres(image, stripe))
                except Exception as e:  # noqa: BLE001 - the audit records every failure
                    crashes[stripe].append(f"{type(e).__name__}: {e}")
                    continue
                res = C.point_errors(uv, gt[C.STRIPE_GT[stripe]], sensor, C.STRIPE_PLANE[stripe])
                pools[stripe].add(*res)
        for stripe in ("h", "v"):
            s = pools[stripe].summary()
            rows.append(dict(condition=name, stripe=stripe, seed=seed + c, **s,
                             crashes="; ".join(crashes[stripe])))  # fmt: skip
        print(f"{name}: {time.time() - t0:.0f} s " + " | ".join(_line(r) for r in rows[-2:]),
              flush=True)  # fmt: skip
    _write(rows, out, frames, seed, names, load_start, time.time() - t0)
    return rows


def _line(r) -> str:
    return (f"{r['stripe']} det {_pct(r['detection_rate'])} gross {_pct(r['gross_rate'])} "
            f"med {_mm(r['median_mm'])} p95 {_mm(r['p95_mm'])}")  # fmt: skip


def _pct(x):
    return "—" if x is None or not np.isfinite(x) else f"{100 * x:.2f}"


def _mm(x):
    return "—" if x is None or not np.isfinite(x) else f"{x:.3f}"


def _write(rows, out, frames, seed, names, load_start, eval_s):
    from cslx.provenance import provenance, provenance_md, write_csv

    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "ood_extraction.csv"), rows, FIELDS + ["seed"])
    prov = provenance(dict(frames=frames, seed=seed, conditions=names))
    md = [
        "# Generality audit: the default extractor on conditions no one tuned for",
        "",
        f"{frames} frame(s) per condition (straight weld, then T-junction), seed {seed} + "
        f"condition index (fresh seeds). Load average at start {load_start}, at end "
        f"{C.load_average()}; {eval_s:.0f} s. Goal of issue 11: detection ≥ 99.5 %, gross "
        "(> 1 mm) ≤ 0.1 %, median ≤ 0.03 mm, p95 ≤ 0.1 mm.",
        "",
        "| condition | stripe | detection % | gross % | median mm | p95 mm | median px | "
        "false pos. | crashes |",
        "|---|---|---:|---:|---:|---:|---:|---:|---|",
    ]
    for r in rows:
        md.append(
            f"| {r['condition']} | {r['stripe']} | {_pct(r['detection_rate'])} | "
            f"{_pct(r['gross_rate'])} | {_mm(r['median_mm'])} | {_mm(r['p95_mm'])} | "
            f"{_mm(r['median_px'])} | {r['false_positives']} | {r['crashes'] or ''} |"
        )
    md += ["", provenance_md(prov), ""]
    with open(os.path.join(out, "ood_extraction.md"), "w", encoding="utf-8") as f:
        f.write("\n".join(md))


if __name__ == "__main__":
    a = C.parser(__doc__, 2, 7400)
    a.add_argument("--only", default="", help="comma-separated condition names")
    args = a.parse_args()
    main(
        frames=1 if args.quick else args.frames,
        seed=args.seed,
        out=args.out,
        only=tuple(n for n in args.only.split(",") if n),
    )
