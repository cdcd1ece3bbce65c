"""Second pass of the linked detector: re-measure each centre along the found path.

The linked detector (`cslx.segmentation.ridges`) must smooth the image along the stripe
(`robust.SIGMA_ALONG`, 6 px along the image axis) to find the weak and sunlit stretches at
all; that smoothing averages neighbouring columns whose stripe lies at other rows wherever
the path curves, and rounds the bead's corners before any centre is measured. Once the path
is known, which ridge is the laser is decided, and each column can be measured again:

1. For every column j of the path (row for the vertical stripe) the monochrome profile is
   convolved with Gaussian derivatives of scale σ across the stripe, evaluated at the
   sub-pixel offsets y = p_j + δ (|δ| ≤ `REACH` px, step `STEP`) from the first pass's
   (smoothed) path p_j: s′(y) = Σ_i f(i) g′(y − i). The kernels are evaluated at the
   continuous offsets, so there is no interpolation.
2. Optionally s′ is averaged over neighbouring path columns at the same offset δ
   (`sigma_along` px, a Gaussian normalised over the valid ones): smoothing along the *path*,
   not the image axis, so a curved or cornered stripe is not bent towards its chord — only
   the first pass's own error p − true enters, and that only through its curvature.
3. The centre is the zero crossing of s′ (s′ > 0 before it, ≤ 0 after) nearest δ = 0,
   linearly interpolated between offsets (Steger 1998 eq. (17) in 1-D: the maximum of the
   smoothed profile along the column). Where there is none within the reach the first
   pass's centre is kept.

`second_pass` runs 1–3 and smooths the result along the path (`cslx.segmentation.path`,
one-sided windows as well): step 7 of `cslx.segmentation.robust`. Where the speckle-weighted
profile fit (`cslx.segmentation.profile`) holds, its centres replace those of 1–3, or are
averaged with them where the stripe's tip is clipped (`PROFILE_FIT`, `BLEND`, see
`second_pass`).

Pure JAX, jit- and vmap-able.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

from . import reference
from .path import smooth_path
from .profile import fit_centres
from .ridges import PATH_HALF_WINDOW, _path_scatter, noise_std

__all__ = [
    "BLEND",
    "BLEND_MAX_CLIPPED",
    "FIT_BORDER",
    "FIT_CHI2",
    "FIT_MAX_CLIPPED",
    "FIT_SHARE",
    "PRECISION_CAP",
    "PRECISION_POWER",
    "PRECISION_WEIGHTS",
    "PROFILE_FIT",
    "REACH",
    "REFINE_CORRELATION",
    "REFINE_HALVES",
    "SIGMA_REFINE",
    "STEP",
    "refine_centres",
    "second_pass",
]

#: Largest distance (px) of the re-measured centre from the first pass's path.
REACH = 2.0
#: Spacing (px) of the offsets at which the profile's derivative is evaluated.
STEP = 0.25


@functools.partial(jax.jit, static_argnames=("sigma", "sigma_along", "axis"))
def refine_centres(
    mono, pos, valid, *, sigma: float, sigma_along: float, axis: int, precision=None
):
    """Centres re-measured around the path `pos` (module docstring).

    Args:
        mono: (H, W) monochrome image, bright stripe.
        pos, valid: (N,) first-pass centres along the search axis and their mask.
        sigma: Gaussian scale across the stripe (px, static).
        sigma_along: smoothing along the path (px, static; 0: none).
        axis: 0 horizontal stripe (one centre per column), 1 vertical.

    Returns:
        (pos, found): the re-measured centres (the first pass's where nothing was found or
        not valid) and the mask of centres that were re-measured.
    """
    x = mono.T if axis == 0 else mono  # (N, M): one row per path column
    n, m = x.shape
    dtype = x.dtype
    p = jnp.where(valid, jnp.nan_to_num(pos), 0.0)
    half = int(math.ceil(REACH + 4 * sigma))
    base = jnp.round(p).astype(jnp.int32)
    taps = jnp.arange(-half, half + 1)
    idx = jnp.clip(base[:, None] + taps[None, :], 0, m - 1)
    f = jnp.take_along_axis(x, idx, 1)  # (N, T)
    f = f - jnp.mean(f, axis=1, keepdims=True)
    k = int(round(REACH / STEP))
    delta = jnp.asarray(np.arange(-k, k + 1) * STEP, dtype)
    # u = y − i for y = p + δ and the tapped rows i = base + taps.
    u = (p - base)[:, None, None] + delta[None, :, None] - taps[None, None, :].astype(dtype)
    g = jnp.exp(-0.5 * (u / sigma) ** 2)
    s1 = jnp.einsum("nt,nkt->nk", f, -u / sigma**2 * g)  # s′(p + δ), up to a constant
    w = valid.astype(dtype)
    if precision is not None:
        w = w * precision  # per-column weights of the along-path average (`second_pass`)
    if sigma_along > 0:
        r = int(math.ceil(3 * sigma_along))
        kern = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_along) ** 2)
        kern = jnp.asarray(kern / kern.sum(), dtype)

        def along(a):
            return jax.vmap(lambda c: jnp.convolve(c, kern, mode="same"), 1, 1)(a)

        norm = jnp.convolve(w, kern, mode="same")
        s1 = along(s1 * w[:, None]) / jnp.maximum(norm, 1e-6)[:, None]
    a, b = s1[:, :-1], s1[:, 1:]
    cross = (a > 0) & (b <= 0)
    frac = a / jnp.where(cross, a - b, 1.0)
    where = delta[:-1][None, :] + STEP * frac  # (N, 2k)
    dist = jnp.where(cross, jnp.abs(where), jnp.inf)
    best = jnp.argmin(dist, axis=1)
    found = valid & jnp.isfinite(jnp.min(dist, axis=1))
    new = p + jnp.take_along_axis(where, best[:, None], 1)[:, 0]
    return jnp.where(found, new, pos), found


#: Smoothing along the path (px) of the second pass. Development frames (seeds 7100–7117,
#: 2 frames × 18 conditions, H / V p95 mm; without the second pass 0.190 / 0.224): with the
#: first pass's 9 px border margin 0 / 2 / 3 / 4 / 6 px → 0.283 / 0.322 (gross 0.12 / 0.29 %),
#: 0.220 / 0.250, 0.207 / 0.230, 0.195 / 0.220, 0.180 / 0.203; without it (as used) 6 / 8 px →
#: 0.173 / 0.198 and 0.171 / 0.198, medians 0.039 / 0.046 and 0.041 / 0.048 mm.
SIGMA_REFINE = 6.0
#: Half windows of the second pass's path smoothing (`path.smooth_path`, one-sided windows
#: too) and its correlation c: see `second_pass`; c 6 → 8 with `LINES` (`path`, "Local lines").
REFINE_HALVES = (2, 4, 8, 16, 32, 64, 96, 128, 192, 256)
REFINE_CORRELATION = 8.0
#: Local lines (curvature from ±`path.CURVATURE_HALF` centres) join the final smoothing's
#: quadratics (`path.smooth_path(lines=True)`; evidence in `cslx.segmentation.path`).
LINES = True
#: Second smoothing weighted by each centre's local precision (`second_pass`, `_local_weights`):
#: on/off, the along-path Gaussian σ (centres) of the local residual variance, the power of the
#: relative precision and the weights' bounds.
LOCAL_WEIGHTS = True
LOCAL_SIGMA = 16.0
LOCAL_POWER = 0.5
LOCAL_BOUNDS = (0.2, 5.0)


def _along(values, weights, sigma_along: float):
    """Gaussian average (σ `sigma_along` centres) of `values` along the path, normalised over
    `weights`: (average, total weight of the kernel), each (N,)."""
    r = int(math.ceil(3 * sigma_along))
    kern = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_along) ** 2)
    kern = jnp.asarray(kern / kern.sum(), values.dtype)
    num = jnp.convolve(jnp.where(weights > 0, values * weights, 0.0), kern, mode="same")
    den = jnp.convolve(weights, kern, mode="same")
    return num / jnp.maximum(den, 1e-9), den


#: Re-measure the centres by the speckle-weighted profile fit (`cslx.segmentation.profile`)
#: where it holds (`second_pass`).
PROFILE_FIT = True
#: A fit holds where its normalised χ² is below `FIT_CHI2`; the fitted centres are used
#: where at least `FIT_SHARE` of the centres within the along-path smoothing hold, and not
#: within `FIT_BORDER` centres of the path's ends.
FIT_CHI2 = 2.0
FIT_SHARE = 0.8
FIT_BORDER = 0
#: Most clipped pixels within REACH + 2σ of the path where the fit is used.
FIT_MAX_CLIPPED = 3
#: Where the fit holds but `FIT_MAX_CLIPPED` < clipped pixels ≤ `BLEND_MAX_CLIPPED` (a
#: clipped tip in sunlight, glare or a green / blue laser), the centre is the mean of the
#: fit's and the derivative's, with weight `BLEND` on the fit's (`second_pass`).
BLEND_MAX_CLIPPED = 7
BLEND = 0.5
#: Average the profile fit's centres along the path as offsets from the first pass's path,
#: not as positions (`second_pass`, "Offsets, not positions").
FIT_RELATIVE = True
#: Weight each column's derivative in the along-path average of `refine_centres` by the
#: profile fit's predicted precision (`_precision`; `second_pass`, "Precision weights").
PRECISION_WEIGHTS = False
#: Power of the relative precision used as the weight, and its cap (× the path's median).
PRECISION_POWER = 0.5
PRECISION_CAP = 10.0


@functools.partial(jax.jit, static_argnames=("sigma", "axis", "sigma_along"))
def second_pass(
    mono, pos, valid, bridged, clipped=None, *, sigma: float, axis: int, sigma_along=None,
    interpolate=None,
):  # fmt: skip
    """Second pass of the linked detector (`cslx.segmentation.robust`, step 7): centres
    re-measured along the first pass's smoothed path (`refine_centres`), then smoothed
    again (`path.smooth_path`, with one-sided windows). `sigma_along` is the along-path σ
    (px) of the re-measurement and of the fit's average; None: `SIGMA_REFINE`
    (`robust.REFINE_PASSES` runs the pass more than once with other σ). `interpolate` (N,)
    marks centres not to measure: they take the final smoothing's value through the others
    (`cslx.segmentation.crossing`: a turned cross's crossing, profiles cut by the border).

    The re-measurement returns p + G∗(c − p) (p the path it is given, c the truth, G the
    along-path Gaussian), so its error is −(I − G)(c − p): the part of the given path's
    error narrower than G passes whole — at the bead's toes, the first pass's rounding of
    the kink (see `robust.REFINE_PASSES` for what re-running the pass does). The metric is
    not the cause (issue 11): on the development frames (seeds 7100–7117, frames 0–1) the
    distance of each triangulated centre to the true 3-D stripe (a polyline through the
    ground-truth points) instead of to the ground-truth point of its column gives H / V
    median 0.0294 / 0.0309 mm, p95 0.131 / 0.140 against 0.0300 / 0.0313, 0.135 / 0.144:
    the stripe's slope in the image stretches the per-column error by ≤ 3 %.

    Bridged centres keep the first pass's line. No border margin: the smoothing along the
    path is normalised over the centres it has, so it does not mirror the image at the
    border (development frames, border centres H / V p95 0.276 / 0.497 mm with the first
    pass's 9 px margin, 0.187 / 0.330 mm without).

    The final smoothing. The error left after it varies slowly along the path (development
    frames: a 41-centre running mean of the signed error has median 0.031 px against the
    error's 0.037 px), i.e. it is the speckle averaged by the windows, and it is largest
    where the windows must stay short: next to the bead's corners (median 0.137 px within 8
    centres) and at the border. One-sided windows (`sided`) let a centre next to a corner
    average the plate on its own side; windows up to ±256 and c = 6 (the speckle left after
    `SIGMA_REFINE` is correlated over more than the 4 centres of the first pass) average
    longer plates. Development frames (seeds 7100–7117, 2 frames × 18 conditions, H / V,
    median / p95 mm): symmetric windows up to ±96, c 4: 0.038 / 0.169, 0.043 / 0.191; up to
    ±192: 0.036 / 0.167, 0.040 / 0.186; ±256: 0.036 / 0.168, 0.039 / 0.184; ±256, c 6:
    0.036 / 0.174, 0.038 / 0.184; one-sided as well, ±96: 0.039 / 0.165, 0.046 / 0.183;
    ±192, c 6: 0.035 / 0.154, 0.040 / 0.174; ±192, c 8: 0.035 / 0.155, 0.039 / 0.172;
    ±256, c 6 (used before `LINES`): 0.035 / 0.153, 0.039 / 0.169 (corners 0.137 → 0.094 px);
    the same with Γ 2.5: 0.035 / 0.154, 0.038 / 0.168; only the most precise of the three
    windows instead of their inverse-variance mean (±192, c 6): 0.035 / 0.169,
    0.039 / 0.185; one-sided windows in the first pass's smoothing as well: no change
    (0.035 / 0.153, 0.039 / 0.168). Detection unchanged (100 / 99.90 %), gross 0.004 /
    0.070 → 0.026 / 0.075 % (1 → 6 and 12 → 13 centres, in stretches that were already
    0.8–1.1 px off before: a printed bead, a sunny frame's vertical stripe).

    The profile fit (`PROFILE_FIT`, `_fitted`). Where it holds, each centre is the
    speckle-weighted Gaussian fit of `cslx.segmentation.profile` (linear background,
    clipped pixels excluded), averaged along the path by the same Gaussian (`SIGMA_REFINE`),
    instead of the Gaussian derivative's zero crossing. Why: the error left on the plates
    of the development frames is speckle (unbiased: the signed error's mean per condition
    and stripe is within ±0.02 px, per frame ±0.04 px; no offset to correct), and the
    derivative weights the core where the fit weights the flanks, which carry more of the
    information under multiplicative noise: a quadratic through each plate's re-measured
    centres (an oracle segmentation of the plate) has an RMS error of 0.045 / 0.020 px
    (derivative / fit) on the clean frames. It holds where its normalised χ² is below
    `FIT_CHI2` for `FIT_SHARE` of the centres in the along-path window, at most
    `FIT_MAX_CLIPPED` pixels within REACH + 2σ are clipped (a clipped tip; saturated
    cores, clipped over 9+ px, keep the derivative on the filled core: there the fit of
    the far flanks moved the flat wall's centres by up to 0.48 px), and not within
    `FIT_BORDER` centres of the path's ends (the one-sided smoothing windows there
    extrapolate the fit's noisier centres: vertical border p95 0.27 → 0.55 mm without
    it). Development frames (seeds 7100–7117, 2 frames × 18 conditions, H / V, median /
    p95 mm): 0.035 / 0.153, 0.039 / 0.169 → 0.031 / 0.145, 0.033 / 0.153 (clean
    0.045 / 0.170, 0.045 / 0.199 → 0.026 / 0.102, 0.026 / 0.122; glare V 0.047 → 0.034,
    shadow V 0.059 → 0.037; worse: green V 0.044 → 0.047, printed V 0.038 → 0.043,
    printed H p95 0.170 → 0.181); detection unchanged (100 / 99.90 %), gross
    0.026 / 0.075 → 0.022 / 0.075 %. Without the clipped-pixel gate: 0.031 / 0.135,
    0.035 / 0.165 (but the flat wall's worst RMS 0.066 → 0.080 px); without any gate
    (every fitted centre): 0.039 / 0.182, 0.047 / 0.234. Flat wall (seeds 41–46):
    unchanged, every figure (RMS ≤ 0.066 px). Cost: the fit step 15–17 ms per stripe
    against 1.6–2.2 ms for the derivative's (jitted, 640×480 frames, load 6–7).

    The blend (`BLEND`, `BLEND_MAX_CLIPPED`). In sunlight, glare and with a green or blue laser
    the stripe's tip is clipped in most columns (4–7 clipped pixels within REACH + 2σ), and the
    fit is used for only 2–13 % of the centres. There, before the final smoothing, the fit's and
    the derivative's errors are only partly correlated (0.24–0.42 with 4–7 clipped pixels) and
    neither is better: p95 0.181 / 0.188 px (H, fit / derivative), 0.235 / 0.184 (V); their mean
    0.151, 0.166. Development frames (as above, H / V median / p95 mm): 0.031 / 0.145, 0.033 /
    0.153 → 0.030 / 0.137, 0.033 / 0.150 (sunny H 0.036 / 0.152 → 0.034 / 0.142, V 0.038 / 0.326
    → 0.037 / 0.270; glare 0.036 / 0.174 → 0.033 / 0.158, 0.034 / 0.150 → 0.032 / 0.138; shadow
    V 0.037 / 0.157 → 0.035 / 0.139; green H p95 0.126 → 0.118, V median 0.047 → 0.043; blue H
    0.033 / 0.162 → 0.031 / 0.150, V p95 0.129 → 0.131; clean, saturated and printed within
    0.001 mm); detection unchanged (100 / 99.90 %), gross 0.022 / 0.075 → 0.022 / 0.064 %.
    Weight 0.3 up to 7 clipped pixels: H / V p95 0.140 / 0.149; 0.5 up to 12: 0.136 / 0.150; 0.7
    up to 12: 0.135 / 0.155; the blend everywhere instead of the fit (0.5, up to 7): clean 0.026
    / 0.102 → 0.034 / 0.130 (the fit's errors average out along the path better than the
    derivative's); the fit alone up to 7 clipped pixels: V p95 0.165. Flat wall (seeds 41–46):
    unchanged, every figure (RMS ≤ 0.066 px, none beyond 0.5 px; the saturated cores clip 9+
    pixels). Cost: not measurable (second pass 12–19 ms either way, sunny frames, load 8).

    Offsets, not positions (`FIT_RELATIVE`, issue 11). The fitted centres c_j are averaged
    along the path as c_j − p_j (p the first pass's path) and added back to p_j, as the
    derivative's along-path average does by construction; averaging the positions
    themselves bent every curve towards its chord by ≈ c''σ²/2 (the bead's caps) and more
    at its toes. Development frames (seeds 7100–7117, 2 frames × 18 conditions, H / V
    median / p95 mm, same frames): 0.0304 / 0.137, 0.0327 / 0.150 → 0.0300 / 0.136,
    0.0314 / 0.147 (clean caps median 0.075 → 0.041 mm H, 0.078 → 0.049 V). With offsets the
    border gate `FIT_BORDER` (which kept the position average from extrapolating at the
    path's ends) is no longer needed: 12 → 0 centres, 0.0300 / 0.135, 0.0313 / 0.144
    (vertical border centres median / p95 0.072 / 0.295 → 0.060 / 0.257 mm); detection
    (100 / 99.90 %) and gross (0.022 / 0.064 %) unchanged; flat wall (seeds 41–46): every
    figure identical; no added cost (one subtraction per centre). Tried with it and not
    kept: `SIGMA_REFINE` 5 / 8 (0.031 / 0.136, 0.031 / 0.145; 0.032 / 0.142, 0.036 /
    0.148); `FIT_MAX_CLIPPED` 5 (0.030 / 0.132, 0.032 / 0.146); `BLEND` 0.7 (0.030 / 0.132,
    0.032 / 0.146, V gross 0.070 %); running the whole second pass twice around its own
    output (0.030 / 0.132, 0.032 / 0.147, H gross 0.035 %, +≈ 20 ms).

    Local weights (`LOCAL_WEIGHTS`, issue 11, the p95). The final smoothing is run twice: the
    second time each centre's fits weigh it by its local precision (`_local_weights`: the first
    smoothing's residual variance over ±`LOCAL_SIGMA` centres, relative to the path's median, to
    the power `LOCAL_POWER`, bounded by `LOCAL_BOUNDS`), so a stretch that scatters more
    (speckle, a glint's edge, a dark square of a printed target) does not pull the quiet centres
    next to it (tests/segmentation/test_path.py: 0.018 → 0.007 px RMS on synthetic paths).
    Development seeds 7100–7117, 18 conditions, H / V median / p95 mm: frames 0–1 (36,
    `experiments.robust_extraction`) 0.0300 / 0.1347, 0.0313 / 0.1438 → 0.0297 / 0.1336, 0.0312
    / 0.1398 (clean V p95 0.124 → 0.115, sunny V median 0.040 → 0.038; worse: glare medians
    0.033 → 0.036 H, 0.031 → 0.034 V, blue H p95 0.151 → 0.153, green V p95 0.123 → 0.125,
    printed V p95 0.186 → 0.188); fresh frame 2 (18, not used to choose): 0.0290 / 0.1397,
    0.0358 / 0.1517 → 0.0283 / 0.1346, 0.0346 / 0.1495; detection and gross unchanged (100 /
    99.90 %, 0.022 / 0.064 % on frames 0–1; 0 on frame 2). Flat wall (seeds 41–46): RMS smaller
    in 19 of 24 frame-stripes, worst 0.066 → 0.064 px, none beyond 0.5 px. Chosen on frames 0–1
    as the only one of three settings that kept both medians (the final smoothing alone, first
    pass as recorded): σ 16, power 1: 0.0297 / 0.1313, 0.0315 / 0.1374 (frame 2: 0.0287 /
    0.1352, 0.0357 / 0.1504); σ 32, power 1: 0.0296 / 0.1316, 0.0314 / 0.1373 (0.0287 / 0.1343,
    0.0361 / 0.1534); σ 32, power 0.5, frame 2 only: 0.0285 / 0.1374, 0.0356 / 0.1507. Also
    tried and not kept (final smoothing alone, frames 0–1): a floor τ on the ICI's standard
    deviations, √(sd² + τ²), τ = 0.1 / 0.2 / 0.3 × scatter (0.0302 / 0.1351, 0.0311 / 0.1437;
    0.0308 / 0.1370, 0.0312 / 0.1441; 0.0322 / 0.1388, 0.0309 / 0.1455); one-sided windows that
    leave out the 3 / 6 centres next to the centre (the rounded toe; extrapolated): 0.0300 /
    0.1355, 0.0310 / 0.1476 and 0.0305 / 0.1434, 0.0309 / 0.1521; a correlation c per path
    measured from the scatter of 8 / 16 / 32-centre block means (c ≈ 1.7 / 15 / 60: the error
    grows with the scale, and the blocks see the bead's shape): 0.0365 / 0.1525, 0.0431 /
    0.1575; 0.0323 / 0.1390, 0.0307 / 0.1463; 0.0409 / 0.1490, 0.0324 / 0.1500. Where the tail
    is left: 74 % of the centres above the p95 (both stripes) were already above it in the
    re-measured centres before any smoothing. Cost: the final smoothing 3.3 → 8.5 ms
    (H) and 2.4 → 6.4 ms (V) per stripe (jitted, a sunny development frame, interleaved, median
    of 15, load ≈ 8 on the shared 2-core machine).

    Precision weights (`PRECISION_WEIGHTS`, off; issue 11, printed targets). Where the
    printed target's error comes from (development frames, seeds 7116–7117, 4 frames, errors
    against the true path; reflectance from the noise-free rendering): 77 % of the centres
    above the p95 lie over black squares (laser light 7.5 % of the white's; H / V pixel
    median 0.046 / 0.045 against 0.031 / 0.031 on white), and most of them more than 6 px
    from a reflectance edge; centres within 1 px of an edge are 14 / 11 % of the centres
    and 24 / 1 % of those above the p95. So the printed error is the faint stripe's noise on
    black, not the division at the edges: `refine_centres` averages the columns' derivatives
    along the path with equal weights, and the regularised division (`REFLECTANCE_FLOOR`)
    lifts the black columns' noise with their signal. With the weights each column's
    derivative counts by (1 / sd²)^`PRECISION_POWER` (`_precision`: sd the profile fit's
    predicted std, × √χ²; columns with more than `FIT_MAX_CLIPPED` clipped pixels near the
    path weigh as the median). Development frames (seeds 7100–7117, 2 frames × 18 conditions,
    H / V median / p95 mm): 0.0300 / 0.135, 0.0313 / 0.144 → 0.0292 / 0.132, 0.0301 / 0.146
    (printed 0.038 / 0.171, 0.043 / 0.186 → 0.027 / 0.151, 0.027 / 0.210; clean V p95
    0.124 → 0.126; the other conditions within ±0.001 mm median, p95 within ±0.003), gross
    0.022 / 0.064 → 0.000 / 0.064 %, detection unchanged; flat wall (seeds 41–46)
    identical. Power 1: 0.0293 / 0.132, 0.0301 / 0.145 (printed 0.029 / 0.157, 0.028 /
    0.206). The pooled vertical p95 gets worse (printed V: per frame 0.258 / 0.240 / 0.065 /
    0.097 → 0.237 / 0.245 / 0.091 / 0.101 mm, the straight frames' medians 0.013 / 0.044 →
    0.020 / 0.010), so the weights stay off. Tried on the printed frames (seeds 7116–7117,
    H / V median / p95 mm, unweighted 0.038 / 0.171, 0.043 / 0.186): weights on every
    column, clipped ones included (power 1): all conditions 0.0328 / 0.142, 0.0330 / 0.156
    (the clipped columns' fits see only the flanks: saturated H median 0.023 → 0.034); each
    column's derivative scaled to unit amplitude as well: 0.029 / 0.163, 0.028 / 0.218; the
    scaling alone 0.054 / 0.283, 0.053 / 0.237; with the scaling, the weights also in the
    fit's along-path average: 0.028 / 0.153, 0.028 / 0.212, and smoothed along the path (σ 3
    / 8 px):
    0.033 / 0.191, 0.047 / 0.218 and 0.044 / 0.255, 0.051 / 0.228 (the gain is per column,
    not per square); without the χ² factor 0.031 / 0.169, 0.024 / 0.203; cap 4: 0.028 /
    0.159, 0.030 / 0.213; power 1.5: 0.033 / 0.166, 0.029 / 0.204.

    Where the error is left (after the above; development frames, regions by the true
    path: caps > 0.3 px off a robust quadratic, toes within 10 centres of a bend, ±12
    centres about the other stripe, 12 at the ends), H / V: plates (with or without a
    clipped tip, 82 %) median 0.026–0.029 mm, p95 0.10–0.14, 41 / 45 % of the errors above
    the p95; caps (8 %) 0.066 / 0.076, p95 0.23 / 0.30, 33 / 32 %; toes (2 / 0.5 %) 14 /
    5 %; the crossing 9 / 3 %; the ends 3 / 16 %. The caps' error varies slowly
    along the path (a 15-centre running mean keeps 83 / 89 % of its RMS) and is hardly
    signed by the curvature (mean 0.02 px): glints and sheen on the bead (glare, sunny,
    green, blue), not rounding. The vertical stripe's median is larger in mm although it is
    smaller in pixels (0.026 against 0.030 px): its plane maps one pixel to 1.19 mm /
    1.02 mm of the horizontal's (median ratio), so it needs 16 % less pixel error.

    Before the offsets, and what did not reduce it (same 36 development frames, H / V
    median / p95 mm, before the blend: 0.031 / 0.145, 0.033 / 0.153). By the true path's shape:
    plates (87 / 89 % of the centres) 0.028 / 0.108, 0.031 / 0.120; bead caps (the true path >
    0.3 px off a robust quadratic through it; 7 / 6 %) 0.075 / 0.249, 0.082 / 0.367; within 10
    centres of a toe (7 / 5 %) 0.079 / 0.344, 0.096 / 0.368 — the caps and toes hold 65 / 59 %
    of the errors above the p95. At the toes the error is the corner's rounding (the error
    signed by the true path's curvature averages 0.16 / 0.17 px of the mean 0.18 px). The fit is
    used for 24 / 25 % of the centres: 92–94 % on clean frames, 2–13 % in sunlight, green, blue
    and printed frames (the clipped-pixel gate; printed: χ²), 0 % on saturated cores. Measured
    and not kept: ρ 0.25, 0.2, 0.5 with `FIT_CHI2` rescaled (0.032 / 0.144–0.149, 0.033–0.035 /
    0.153–0.155); `FIT_CHI2` 3 / 5, `FIT_SHARE` 0.6 / 0.95 (p95 0.143–0.152, 0.154–0.165);
    `FIT_MAX_CLIPPED` 5 / 7 / 9 / 12 (H p95 0.137 / 0.135 / 0.134 / 0.134, V 0.157 / 0.165 /
    0.164 / 0.166: the flanks' fit helps the horizontal stripe and hurts the vertical); fit
    windows REACH + 2.5σ / 3σ / 5σ (within ±0.002 mm); `SIGMA_REFINE` 3 / 4 / 8 with c = σ (H
    toes p95 0.344 → 0.289 at 3 px, plates 0.108 → 0.115; overall H / V p95 0.148 / 0.161, 0.144
    / 0.157, 0.148 / 0.160); after the smoothing, the corners redrawn as the max / min of the
    two one-sided lines (±24 centres, 8 px guard) where their slopes differ (p95 0.161–0.176,
    0.156–0.170: the caps are not lines); a curvature correction p − β p″ (local quadratics
    ±6–12, β 5–20: H / V p95 0.148–0.172 / 0.157–0.174); the smoothing repeated without the
    centres more than κ × scatter from the first (κ 2: 0.031 / 0.144, 0.033 / 0.150; κ 3 / 4:
    within 0.001 mm).

    What limits it now, and what did not pay (issue 11, the vertical stripe's median and
    both p95s; development frames seeds 7100–7117, frames 0–1 (36) unless noted, H / V
    median / p95 mm, as used: 0.0300 / 0.135, 0.0313 / 0.144; frames 0–2 (54): 0.0297 /
    0.136, 0.0326 / 0.147; frame 0 (18): 0.0301 / 0.131, 0.0317 / 0.135. "Curved": centres
    whose true path is > 0.3 px off its own ±15-centre line, the caps' and toes' sharpest
    bends, 2 % of the centres).

    - The error left is not speckle-grain noise. Frame 0, plates: the per-column
      derivative's error (no along-path average) has RMS 0.16–0.53 px, and its 201-centre
      running mean still 0.013–0.068 px (white noise would leave 0.27 / √201 = 0.019); the
      final centres' RMS is 0.018–0.091 px, of which a 15-centre running mean keeps 75–100 %
      (median 90 %) and a 61-centre one 43–95 % (median 69 %). It varies over tens to
      hundreds of centres, where the speckle (grain 1.2 px) is long averaged out, so a
      longer or more anisotropic average along the stripe has little left to remove
      (`SIGMA_REFINE` 5 / 8 above). It correlates (+0.1 to +0.77 per frame) with the first
      pass's own high-frequency error p − G₆∗p, because both measure the same image.
    - Re-measuring around a smoothed first-pass path (so the offsets carry none of its
      high-frequency error): Gaussian σ 6: 0.0301 / 0.132, 0.0315 / 0.145; local quadratic σ
      12 / 20: 0.0301 / 0.133, 0.0311 / 0.142 and 0.0303 / 0.135, 0.0313 / 0.145, but the
      curved centres' median 0.149 / 0.154 px → 0.166 / 0.163, 0.167 / 0.188, 0.203 / 0.229
      (the bead's bends rounded) and sunny straight H p95 0.166 → 0.182–0.194: not kept.
    - The derivative's σ (`sigma`, from the measured width per stripe, `robust.stripe_sigma`)
      × 0.8 (2 px on most frames): 0.0301 / 0.133, 0.0318 / 0.138 (cross printed V 0.0756 /
      0.248 → 0.0667 / 0.206; straight green H median 0.0388 → 0.0457, straight sunny V p95
      0.313 → 0.332); × 1.2 (18 frames): 0.0306 / 0.139, 0.0319 / 0.140 (as used 0.0301 /
      0.131, 0.0317 / 0.135): not kept.
    - The fit's along-path average weighted against glints and sheen (54 frames): each
      fitted centre by 1 / max(χ², 1): 0.0293 / 0.136, 0.0321 / 0.146 (straight clean V
      median 0.0153 → 0.0174, sunny V p95 0.187 → 0.195 and 0.199 → 0.207, cross shadow V
      median 0.0354 → 0.0369; curved median 0.140 → 0.142 px H: the caps gain nothing);
      by 1 / max(χ², 1)²: 0.0298 / 0.135, 0.0306 / 0.142 on 36 frames (1 / χ²: 0.0297 /
      0.135, 0.0306 / 0.143); by the inverse predicted variance 1 / (sd² max(χ², 1)),
      relative to the path's median, capped at 10, power 1 / 0.5: 0.0295 / 0.137, 0.0323 /
      0.145 and 0.0294 / 0.136, 0.0322 / 0.145. Gains ≤ 1.5 % against single conditions
      4–14 % worse: not kept.
    - A bias of the vertical stripe. Its signed error (mean over frame 0's 14 unsaturated
      frames of the per-frame median, plates) is −0.013 px (11 of 14 negative) in the
      per-column derivative at σ 1.5 / 2.5 / 3.5 (−0.016 / −0.013 / −0.012), in the profile
      fit (−0.011) and in the final centres (−0.013); the horizontal's −0.005 / −0.005 /
      +0.001, −0.004, +0.003. Shifting the vertical centres by +0.01 px would take its
      median 0.0317 → 0.0273 mm (18 frames) — more than anything above — but an offset fitted
      to the renderer is not a method. It comes with the speckle: the straight clean scenes of
      seeds 7100 / 7102 / 7104 / 7106 (frame 0) rendered again with parts of the image
      formation off, the linked detector's vertical median signed error is, as rendered,
      −0.016 / −0.015 / −0.017 / −0.012 px; without speckle −0.004 / −0.005 / +0.003 /
      +0.002; without shot and read noise −0.022 / −0.020 / −0.033 / +0.003; with neither
      −0.004 / −0.001 / +0.002 / −0.003; with speckle grain 2.4 px −0.016 / −0.030 / −0.010
      / −0.032 (horizontal: ±0.004 without speckle, −0.032 to +0.018 with it, no common
      sign). Without speckle, noise, texture and ambient light, every estimator on the red
      channel (a 3-point log-parabola, a centroid, the derivative at σ 1.5–3.5) puts the
      vertical stripe 0.004–0.006 px left of the truth (horizontal 0.001–0.002), while the
      rendered plane function's zero crossing lies within 4·10⁻⁵ px of it: the profile is
      slightly skewed, and the multiplicative speckle turns that into the larger bias (a
      second-order effect of the estimators under multiplicative noise, presumably). Open:
      an estimator unbiased under multiplicative noise of a skewed profile.
    - Where the vertical stripe loses (dev frames 0–1: H / V median 0.0297 / 0.0312 mm;
      frame 2: 0.0283 / 0.0346). In pixels V is the better stripe (0.026 against 0.029 px);
      its plane maps a pixel to more millimetres (per-frame median ratio 1.19; H 1.01). Its
      ends scatter most: 0.053 / 0.037 px within 12 / 12–48 rows of the top or bottom border
      against 0.024 px further in (20 % of its centres lie within 48 rows of a border), with
      a signed mean of −0.03 to 0 px: scatter, not a bias. The fit's ρ (`profile.RHO`) 0.25 /
      0.5 / 0.7 / 1.0 with `FIT_CHI2` 2: V median frames 0–1 0.0316 / 0.0290 / 0.0293 /
      0.0298, frame 2 0.0356 / 0.0353 / 0.0330 / 0.0325 mm, but the V p95 on frames 0–1 rises
      (0.7: 0.140 → 0.145) and printed H loses (0.7: 0.0367 → 0.0382): not kept. With the
      gate held fixed (`FIT_CHI2` × (0.35 / ρ)²) every figure gets worse at ρ 0.7 (V 0.0377 /
      0.0439): the gain came with the looser gate, whose p95 cost was measured before.
    """
    sa = SIGMA_REFINE if sigma_along is None else float(sigma_along)
    use = valid & ~bridged
    # `interpolate` (`cslx.segmentation.crossing`): not measured, the final fit's value
    fill = jnp.zeros_like(use) if interpolate is None else use & interpolate
    use = use & ~fill
    if reference.RAW_REFERENCE:  # off: `cslx.segmentation.reference`
        pos = reference.raw_reference(mono, pos, use, sigma=sigma, axis=axis)
    fitted, prec = None, None
    if PROFILE_FIT or PRECISION_WEIGHTS:  # one profile fit for both
        half = int(math.ceil(REACH + 4 * sigma))
        excl = jnp.zeros(mono.shape, bool) if clipped is None else clipped
        fitted = fit_centres(
            mono, pos, use, excl, noise_std(mono), half=half, axis=axis, reach=REACH
        )
    if PRECISION_WEIGHTS:
        unclipped = _clipped_near(excl, pos, sigma=sigma, axis=axis) <= FIT_MAX_CLIPPED
        prec = _precision(fitted, use, unclipped)
    # refine_centres keeps `pos` wherever `use` is False or nothing was found
    new, _ = refine_centres(mono, pos, use, sigma=sigma, sigma_along=sa, axis=axis, precision=prec)
    if PROFILE_FIT:
        new = _fitted(mono, pos, use, new, clipped, fitted, sigma=sigma, axis=axis, sigma_along=sa)
    new = jnp.nan_to_num(new)
    # the path's scatter (the ICI's noise model) over every measurable centre, as without
    # `interpolate`: excluding a crossing's few columns would change every window (audit,
    # cross turned 20°, seed 7405: V median 0.0241 → 0.0233 mm; 0.0231 not interpolated)
    scatter = _path_scatter(new, use | fill, 2 * PATH_HALF_WINDOW)

    def smooth(weights=None):
        kw = dict(correlation=REFINE_CORRELATION, halves=REFINE_HALVES, sided=True, lines=LINES)
        return smooth_path(new, valid, scatter, support=use, weights=weights, **kw)[0]

    smoothed = smooth()
    if LOCAL_WEIGHTS:
        smoothed = smooth(_local_weights(new, smoothed, use))
    return jnp.where(use | fill, smoothed, pos)


def _local_weights(new, smoothed, use):
    """Per-centre weights of the second smoothing (`LOCAL_WEIGHTS`): the residual of the
    first smoothing, r = new − smoothed, gives each centre's local variance v_j = G∗(r² ·
    use) / G∗use (G a Gaussian of `LOCAL_SIGMA` centres along the path); the weight is
    (median over the path of v / v_j)^`LOCAL_POWER`, within `LOCAL_BOUNDS`. A stretch of the
    path whose centres scatter more (speckle, a glint's edge, a dark patch of a printed
    target) counts less in the fits around it; a typical centre has weight ≈ 1, so the
    ICI's noise model (scatter × factor) keeps its meaning."""
    r = int(math.ceil(3 * LOCAL_SIGMA))
    kern = np.exp(-0.5 * (np.arange(-r, r + 1) / LOCAL_SIGMA) ** 2)
    kern = jnp.asarray(kern, new.dtype)
    u = use.astype(new.dtype)
    res = jnp.where(use, new - smoothed, 0.0)
    v = jnp.convolve(res**2 * u, kern, mode="same") / jnp.maximum(
        jnp.convolve(u, kern, mode="same"), 1e-6
    )
    med = jnp.nanmedian(jnp.where(use, v, jnp.nan))
    med = jnp.where(jnp.isfinite(med), med, 1.0)
    w = (med / jnp.maximum(v, 1e-12)) ** LOCAL_POWER
    return jax.lax.stop_gradient(jnp.clip(w, *LOCAL_BOUNDS))


def _clipped_near(excl, pos, *, sigma: float, axis: int):
    """Clipped pixels within REACH + 2σ of the path, per centre."""
    x = excl.T if axis == 0 else excl
    near = int(math.ceil(REACH + 2 * sigma))
    rows = jnp.round(jnp.nan_to_num(pos)).astype(jnp.int32)[:, None] + jnp.arange(-near, near + 1)
    rows = jnp.clip(rows, 0, x.shape[1] - 1)
    return jnp.sum(jnp.take_along_axis(x, rows, 1), axis=1)


def _precision(fitted, use, unclipped):
    """Per column, the weight of its derivative in the along-path average
    (`PRECISION_WEIGHTS`): (1 / sd²)^`PRECISION_POWER`, sd the profile fit's predicted std of
    the centre (× √χ² where the fit is worse than its noise model), relative to the median
    over the path's unclipped columns and capped at `PRECISION_CAP`. Unclipped columns
    without a fit get the smallest weight of those with one; columns with more than
    `FIT_MAX_CLIPPED` clipped pixels near the path (whose fit sees only the flanks) get the
    median's, 1."""
    _, found, sd, chi2 = fitted
    var = jnp.where(found, sd**2 * jnp.maximum(chi2, 1.0), jnp.inf)
    prec = jnp.where(found & jnp.isfinite(var), 1.0 / jnp.maximum(var, 1e-12), 0.0)
    ok = use & (prec > 0) & unclipped
    ref = jnp.nanmedian(jnp.where(ok, prec, jnp.nan))
    prec = jnp.where(ok, prec / jnp.where(jnp.isfinite(ref), ref, 1.0), 0.0)
    low = jnp.min(jnp.where(ok, prec, jnp.inf))
    prec = jnp.where(ok, prec, jnp.where(unclipped & jnp.isfinite(low), low, 1.0))
    return jnp.minimum(prec, PRECISION_CAP) ** PRECISION_POWER


def _fitted(
    mono,
    pos,
    use,
    derivative,
    clipped,
    fitted=None,
    *,
    sigma: float,
    axis: int,
    sigma_along: float = SIGMA_REFINE,
):
    """The profile fit's centres averaged along the path (`SIGMA_REFINE`), where the fit
    holds (`FIT_CHI2`, `FIT_SHARE`, `FIT_BORDER`, `FIT_MAX_CLIPPED`); their mean with
    `derivative` (the centres of `refine_centres`, weights `BLEND`) where it holds with up
    to `BLEND_MAX_CLIPPED` clipped pixels; `derivative` elsewhere. See `second_pass`."""
    sa = sigma_along
    excl = jnp.zeros(mono.shape, bool) if clipped is None else clipped
    if fitted is None:
        half = int(math.ceil(REACH + 4 * sigma))
        fitted = fit_centres(
            mono, pos, use, excl, noise_std(mono), half=half, axis=axis, reach=REACH
        )
    fit, found, _, chi2 = fitted
    dtype = derivative.dtype
    # A clipped core leaves only the flanks, whose fit trades the width against the height
    # and follows the tails' shape: there the derivative's centre (on the filled core) stays.
    n_clipped = _clipped_near(excl, pos, sigma=sigma, axis=axis)
    if FIT_RELATIVE:
        # average the fitted offsets from the path, not the positions (see FIT_RELATIVE)
        base = jnp.nan_to_num(pos)
        off, den = _along(jnp.nan_to_num(fit) - base, found.astype(dtype), sa)
        mean = base + off
    else:
        mean, den = _along(jnp.nan_to_num(fit), found.astype(dtype), sa)
    n = pos.shape[0]
    j = jnp.arange(n)
    first = jnp.min(jnp.where(use, j, n))
    last = jnp.max(jnp.where(use, j, -1))
    inner = (j >= first + FIT_BORDER) & (j <= last - FIT_BORDER)

    def holds_within(most_clipped: int):
        holds = found & (chi2 < FIT_CHI2) & (n_clipped <= most_clipped)
        good, _ = _along(holds.astype(dtype), use.astype(dtype), sa)
        return use & (den > 1e-6) & (good > FIT_SHARE) & inner

    blend = jnp.where(
        holds_within(BLEND_MAX_CLIPPED), BLEND * mean + (1 - BLEND) * derivative, derivative
    )
    return jnp.where(holds_within(FIT_MAX_CLIPPED), mean, blend)
