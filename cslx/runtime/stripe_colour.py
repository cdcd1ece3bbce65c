"""The tracker's colour space on a frame (host-side, NumPy, outside the jit; section 3.1).

The compiled pipeline converts each frame with fixed weights, eq. (8) (R − G by default, the
paper's space for its red laser). Another laser colour defeats them: R − G sees a green
stripe as a *dark* line (its kurtosis is even in the weights, so it stays high: only its
sign betrays it), and Steger's detector, which looks for bright lines, then finds 40–60 gross
centres per stripe and frame at any σ. The tracker (`cslx.runtime.tracker.Tracker`)
therefore checks the space on the first frame after a start or `reset` with both stripes,
together with Steger's σ (`cslx.runtime.stripe_width`):

1. the paper's kurtosis search (`search`): the 74-space integer grid
   (`cslx.segmentation.colour.CANDIDATES`) scored by the normalized kurtosis (eq. (12),
   correction 4) of every 8th column (horizontal stripe) plus every 8th row (vertical
   stripe), pixels with a channel ≥ `cslx.config.SEARCH_CLIP_LEVEL` (240) replaced by the
   frame's median colour as in the robust extractor's clip-aware search
   (`cslx.segmentation.search`), the best space's sign chosen to make the stripes bright
   (positive skewness on both);
2. the configured weights stay unless they clearly fail (`choose_weights`): a stripe is
   dark in them (skewness below `DARK`), or their kurtosis is below `KEEP` × the searched
   space's. Otherwise the searched weights are compiled once (one program per (σ, weights),
   as for σ) and kept until the next reset.

Evidence (`experiments/rig_colour.py`: rendered T scenes on the default rig, clean / sunny
by seed parity, a cold and a tracking frame each, the tracker's pipeline with the tracker's
(σ, weights) after its first frame, σ 2 throughout; gross = centres > 1 mm from the truth
in 3-D per stripe and frame, mean (range); median error, median over frames (range);
horizontal / vertical stripe; load 7–8 on 2 cores), before (R − G) → after (this rule),
dev seeds 8800–8805:

- red laser: R − G kept on every frame, identical (gross 4.4 (0–14) / 2.5 (0–6), median
  0.115 / 0.134 mm). R − G's kurtosis is ≥ 0.90 × the searched space's (2R − G − B or
  R − G) and its skewness ≥ 1.4 on every red dev frame checked: these 12 and the first
  frames of Figure 22's closed loop (seeds 2201, 2203, 2204) and of the tracking sequences
  (7301, 7302, 7305, both placements), every nuisance (clean, sunny, glare, shadow);
- green laser (camera response (0.12, 1, 0.2)): the stripes are dark in R − G (skewness
  −3.3 to −10.9; kurtosis ratio 0.76 sunny, so the kurtosis test alone would not catch
  it): −R + 2G − B chosen on every frame; gross 60.8 (46–87) / 39.2 (13–71) → 5.9 (0–17) /
  3.3 (0–10), median 44.1 / 2.32 mm (R − G's centres lie on the stripes' flanks or the
  background) → 0.113 / 0.137 mm, as good as the red laser's;
- blue laser ((0.04, 0.18, 1)): R − G barely sees it (kurtosis 1.0–1.3 against 83–89,
  ratio ≤ 0.015; skewness −2.5 clean, ≈ 0 sunny): −R − G + 2B chosen on every frame; gross
  52.2 (40–64) / 60.3 (15–159) → 6.0 (0–20) / 2.2 (0–8), median 58.6 / 49.6 → 0.116 /
  0.136 mm.

`KEEP` = 0.5 lies between the red frames' ratios (≥ 0.90) and the blue ones' (≤ 0.015).
Held out (seeds 8810–8813, not used to set the rule; load 2–5): red R − G kept, identical
(4.5 (0–11) / 1.6 (0–5) gross, 0.112 / 0.146 mm); green −R + 2G − B on every frame (R − G
skewness −4.5 to −10.6), gross 53.2 (32–81) / 44.2 (9–89) → 4.1 (0–12) / 2.9 (0–8),
median 41.9 / 1.54 → 0.113 / 0.143 mm; blue −R − G + 2B on every frame (R − G kurtosis
ratio ≤ 0.017 sunny), gross 44.5 (30–57) / 66.0 (16–143) → 3.0 (0–10) / 2.5 (0–7), median
66.4 / 55.4 → 0.111 / 0.147 mm. The audit ran with the dark test at skewness < 0; the
final `DARK` = −1 and `MIN_KURTOSIS` choose the same weights on all 60 first frames (3
lasers × 20 seeds: the blue sunny ones, skewness ≈ 0, switch on the kurtosis test).

Clipped pixels. JPEG leaves a clipped red core at 251–255 with smeared green and blue, so
the sensor's clip level (254) left part of it in the moments and the near-white core scored
for G − B-like spaces. With 240 (the extractor's search level): JPEG q70 saturated frames
(`experiments.ood_extraction`'s condition, fresh seed 7612, 4 frames, weights and σ as the
tracker chooses them, `tracking_config`, a cold frame then a tracking frame): frames 0 and 2
had switched to (0, 1, −1) / (0, 2, −2) at σ 2 px, median 3-D error H 0.287 / 0.322, V 0.353
/ 0.318 mm, gross 3.29 / 4.87 and 9.22 / 7.92 %; they now keep R − G, whose width check
gives σ 5.5 px: H 0.101 / 0.114, V 0.138 / 0.144 mm, gross 1.56 / 2.50 and 2.10 / 3.34 %
(frames 1 and 3 kept R − G before as well: unchanged). The same weights as with 254 on the
65 other frames checked: the 36 of this evidence (red, green and blue, seeds 8800–8805), the
18 development conditions of `experiments.robust_extraction` (seeds 7100–7117, frame 0) and
the default rig's audit conditions of `experiments.ood_extraction` (seed 7400, frame 0; the
one changed frame was JPEG q70 saturated again, to R − G).

The check costs ≈ 18 ms per frame at 640×480 (NumPy, load 4–5; the channels' joint
moments once per stripe as batched matrix products, the configured space scored with the
grid: 100–180 ms in the same run when each space set recomputed them with `einsum`), once
per start or reset; a new (σ, weights) program compiles in ≈ 15–20 s cold under that load (once per
tracker, 0.9 s from a warm persistent cache), so a rig whose laser is known should set its
weights in the configuration (`cslx.runtime.pipeline.PipelineConfig.weights`), or turn
the check off (``Tracker(auto_weights=False)``).
"""

from __future__ import annotations

import numpy as np

from ..config import COLOUR_GRID, SEARCH_CLIP_LEVEL, SEARCH_STRIDE

__all__ = ["CANDIDATES", "DARK", "KEEP", "MIN_KURTOSIS", "choose_weights", "search", "space_scores"]

#: The paper's 74 spaces (`cslx.config.COLOUR_GRID`, as `cslx.segmentation.colour.CANDIDATES`;
#: that module is not imported: it pulls in JAX modules a cached tracker start-up does not load).
CANDIDATES = np.array(COLOUR_GRID, np.float32)
#: The configured weights are kept while their kurtosis is at least this share of the
#: searched space's (module docstring).
KEEP = 0.5
#: A stripe is dark in a space when its mean skewness is below this: red frames ≥ 1.4 in
#: R − G, green ones ≤ −3.3; a frame without a stripe is ≈ 0 (module docstring).
DARK = -1.0
#: Below this summed excess kurtosis the searched space shows no stripe either (noise
#: scores ≈ 0–1; laser frames 40–245): the configured weights stay.
MIN_KURTOSIS = 10.0


def _segments(rgb: np.ndarray, axis: int) -> np.ndarray:
    """(M, N, 3) float: every SEARCH_STRIDE-th column (axis 0) or row (axis 1), pixels with
    a channel ≥ SEARCH_CLIP_LEVEL set to the frame's median colour."""
    x = np.asarray(rgb)
    x = x[:, ::SEARCH_STRIDE] if axis == 0 else x[::SEARCH_STRIDE].transpose(1, 0, 2)
    x = x.astype(np.float32)
    median = np.median(np.asarray(rgb)[::7, ::7].reshape(-1, 3), axis=0).astype(np.float32)
    return np.where(np.any(x >= SEARCH_CLIP_LEVEL, -1, keepdims=True), median, x)


def space_scores(rgb: np.ndarray, weights: np.ndarray, axis: int):
    """(kurtosis, skewness) of each space in `weights` (K, 3) on one stripe's segments:
    the mean over segments of the sample excess kurtosis M k_j − 3 (eq. (12), normalized
    form) and of the skewness (> 0: the stripe is bright). Flat segments count 0."""
    # The moments of every space follow from the channels' joint moments per segment
    # (2nd, 3rd, 4th order: 3 + 27 + 81 numbers), so the K spaces cost no pass over pixels.
    x = _segments(rgb, axis)
    d = x - x.mean(0)
    m, n = d.shape[:2]
    # per segment, as batched matrix products (BLAS): d (n, m, 3), dd (n, m, 9) = d ⊗ d
    d = d.transpose(1, 0, 2)
    dd = (d[..., :, None] * d[..., None, :]).reshape(n, m, 9)
    dt, ddt = d.transpose(0, 2, 1), dd.transpose(0, 2, 1)
    d2 = (dt @ d) / m
    d3 = (ddt @ d).reshape(n, 3, 3, 3) / m
    d4 = (ddt @ dd).reshape(n, 3, 3, 3, 3) / m
    w = np.asarray(weights, np.float32)
    u = np.einsum("nab,ka,kb->kn", d2, w, w, optimize=True)
    f = np.einsum("nabcd,ka,kb,kc,kd->kn", d4, w, w, w, w, optimize=True)
    t = np.einsum("nabc,ka,kb,kc->kn", d3, w, w, w, optimize=True)
    ok = u > 1e-6 * np.maximum(u.max(1, keepdims=True), 1e-12)
    us = np.where(ok, u, 1.0)
    kurt = np.where(ok, f / us**2 - 3.0, 0.0)
    skew = np.where(ok, t / us**1.5, 0.0)
    return kurt.mean(1), skew.mean(1)


def search(rgb: np.ndarray):
    """(weights, kurtosis): the grid space of highest kurtosis summed over both stripes,
    signed so that the stripes are bright (module docstring, step 1)."""
    return _best(*space_scores(rgb, CANDIDATES, 0), *space_scores(rgb, CANDIDATES, 1))


def _best(k0, s0, k1, s1):
    """`search` from the scores of `CANDIDATES` on both stripes."""
    best = int(np.argmax(k0 + k1))
    sign = -1.0 if s0[best] + s1[best] < 0 else 1.0
    return tuple(float(sign * w) for w in CANDIDATES[best]), float(k0[best] + k1[best])


def choose_weights(rgb: np.ndarray, configured) -> tuple[tuple[float, ...], str]:
    """(weights, reason): `configured` unless a stripe is dark in it (`DARK`) or its kurtosis
    is below `KEEP` × the searched space's, then the searched space (module docstring, step 2)."""
    # the configured space scored with the grid (row 0): one moment pass per stripe
    w = np.concatenate([np.asarray(configured, np.float32)[None], CANDIDATES])
    k0, s0 = space_scores(rgb, w, 0)
    k1, s1 = space_scores(rgb, w, 1)
    kept = tuple(float(v) for v in configured)
    best, k_best = _best(k0[1:], s0[1:], k1[1:], s1[1:])
    k_conf = float(k0[0] + k1[0])
    if min(s0[0], s1[0]) < DARK:
        reason = f"stripes dark in {kept} (skewness {s0[0]:.2f} / {s1[0]:.2f})"
    elif k_best >= MIN_KURTOSIS and k_conf < KEEP * k_best:
        reason = f"kurtosis {k_conf:.1f} in {kept} against {k_best:.1f} in {best}"
    else:
        return kept, f"kept (kurtosis {k_conf:.1f}, searched {k_best:.1f} in {best})"
    return best, reason
