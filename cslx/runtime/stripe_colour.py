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
   stripe), clipped pixels replaced by the frame's median colour as in the robust
   extractor's clip-aware search (`cslx.segmentation.robust.search_space_unclipped`), the
   best space's sign chosen to make the stripes bright (positive skewness on both);
2. the configured weights stay unless they clearly fail (`choose_weights`): a stripe is
   dark in them (negative skewness), or their kurtosis is below `KEEP` × the searched
   space's. Otherwise the searched weights are compiled once (one program per (σ, weights),
   as for σ) and kept until the next reset.

Evidence (`experiments/rig_colour.py`; rendered T scenes, clean / sunny by seed parity,
dev seeds 8800–8805, hold-out 8810–8813, a cold and a tracking frame each; gross = centres
> 1 mm from the truth in 3-D per stripe and frame, horizontal / vertical): see the numbers
filled in below by the audit. Red rig: R − G kept on every dev frame checked (Figure 22's
closed loop, seeds 2201, 2203, 2204; tracking sequences 7301, 7302, 7305, first frames).
"""

from __future__ import annotations

import itertools
import math

import numpy as np

__all__ = ["CANDIDATES", "KEEP", "choose_weights", "search", "space_scores"]

#: The paper's grid (section 3.1): w_r ∈ {0, 1, 2}, w_g, w_b ∈ {−2..2}, not all zero; the
#: same 74 spaces as `cslx.segmentation.colour.CANDIDATES` (not imported: it pulls in JAX
#: modules a cached tracker start-up does not load).
CANDIDATES = np.array(
    [w for w in itertools.product(range(3), range(-2, 3), range(-2, 3)) if any(w)], np.float32
)
#: Sensor level from which a pixel counts as clipped (`cslx.segmentation.robust.CLIP_LEVEL`).
CLIP_LEVEL = 254.0
#: Every STRIDE-th column (row) is scored (`cslx.segmentation.robust.SEARCH_STRIDE`).
STRIDE = 8
#: The configured weights are kept while their kurtosis is at least this share of the
#: searched space's (module docstring).
KEEP = 0.5


def _segments(rgb: np.ndarray, axis: int) -> np.ndarray:
    """(M, N, 3) float: every STRIDE-th column (axis 0) or row (axis 1), clipped pixels set to
    the frame's median colour."""
    x = np.asarray(rgb)
    x = x[:, ::STRIDE] if axis == 0 else x[::STRIDE].transpose(1, 0, 2)
    x = x.astype(np.float32)
    median = np.median(np.asarray(rgb)[::7, ::7].reshape(-1, 3), axis=0).astype(np.float32)
    return np.where(np.any(x >= CLIP_LEVEL, -1, keepdims=True), median, x)


def space_scores(rgb: np.ndarray, weights: np.ndarray, axis: int):
    """(kurtosis, skewness) of each space in `weights` (K, 3) on one stripe's segments:
    the mean over segments of the sample excess kurtosis M k_j − 3 (eq. (12), normalized
    form) and of the skewness (> 0: the stripe is bright). Flat segments count 0."""
    # The moments of every space follow from the channels' joint moments per segment
    # (2nd, 3rd, 4th order: 3 + 27 + 81 numbers), so the K spaces cost no pass over pixels.
    x = _segments(rgb, axis)
    d = x - x.mean(0)
    m = d.shape[0]
    d2 = np.einsum("mna,mnb->nab", d, d) / m
    d3 = np.einsum("mna,mnb,mnc->nabc", d, d, d, optimize=True) / m
    dd = np.einsum("mna,mnb->mnab", d, d)
    d4 = np.einsum("mnab,mncd->nabcd", dd, dd, optimize=True) / m
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
    k0, s0 = space_scores(rgb, CANDIDATES, 0)
    k1, s1 = space_scores(rgb, CANDIDATES, 1)
    best = int(np.argmax(k0 + k1))
    sign = -1.0 if s0[best] + s1[best] < 0 else 1.0
    return tuple(float(sign * w) for w in CANDIDATES[best]), float(k0[best] + k1[best])


def choose_weights(rgb: np.ndarray, configured) -> tuple[tuple[float, ...], str]:
    """(weights, reason): `configured` unless a stripe is dark in it or its kurtosis is below
    `KEEP` × the searched space's, then the searched space (module docstring, step 2)."""
    w = np.asarray(configured, np.float32)[None]
    k0, s0 = space_scores(rgb, w, 0)
    k1, s1 = space_scores(rgb, w, 1)
    kept = tuple(float(v) for v in configured)
    best, k_best = search(rgb)
    k_conf = float(k0[0] + k1[0])
    if min(s0[0], s1[0]) < 0:
        reason = f"stripes dark in {kept} (skewness {s0[0]:.2f} / {s1[0]:.2f})"
    elif math.isfinite(k_best) and k_conf < KEEP * k_best:
        reason = f"kurtosis {k_conf:.1f} in {kept} against {k_best:.1f} in {best}"
    else:
        return kept, f"kept (kurtosis {k_conf:.1f}, searched {k_best:.1f} in {best})"
    return best, reason
