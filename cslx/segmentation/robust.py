"""Robust stripe extraction: colour space, clipped cores, width-aware σ, linked ridges.

The method "linked" of `cslx.segmentation.extract` (the default since issue 11):

1. Colour space. Fixed weights, or "auto": the kurtosis search of section 3.1 (the 74-space
   grid of `cslx.segmentation.colour`, normalized form) with clipped pixels replaced by the
   frame's median colour, so a white core does not decide the space
   (`cslx.segmentation.search.search_space_unclipped`). The grid is scored from the
   channels' moments (`_grid_scores`: Σ(I − μ)² and Σ(I − μ)⁴ are a quadratic and a quartic
   form in the weights, so 6 + 15 moment sums per column replace 74 monochrome images; equal
   to `colour.search_space` to rounding, tested) on every `SEARCH_STRIDE`-th column (row): on
   the 72 development searches (seeds 7100–7117, both stripes) the choice equals the full
   search's every time.
2. Clipped cores. A pixel with any channel at the sensor's maximum holds a lower bound, not
   a value. Along the search axis, every run of clipped pixels at most `max_run` long gets the
   constant 1.5 × max(value of its two unclipped neighbours) in the monochrome image
   (`fill_clipped`): a laser core clipped to a plateau (in R) or to a hole (in R − G, where
   R = G = B = 255 maps to 0) becomes one symmetric bump whose centre is the plateau's middle,
   set by its unclipped flanks. White glints have grey flanks (≈ 0 in a laser-coloured space)
   and stay dark. Centres on a filled run are flagged `saturated`.
   On a printed target (many sharp reflectance steps in the darkest channel) the monochrome
   image is first divided by the reflectance (`_reflectance_normalised`).
3. Column profiles and σ (`cslx.segmentation.ridges`, `sigma_along`): the image is smoothed
   by `SIGMA_ALONG` along the stripe and each column's profile is located by the 1-D Taylor
   step, which measures through the crossing of the other stripe (constant along the
   column). σ across the stripe is `SIGMA0`; when the measured profile std s (Steger 1998 §4)
   asks for more — Steger's σ ≥ w/√3 for a bar of half-width w is σ ≥ s, e.g. a filled 15 px
   plateau — a second pass uses σ = `SIGMA_PER_WIDTH` × s within [`SIGMA_MIN`, `SIGMA_MAX`].
   On the development frames σ across changed little (1.5 / 2.5 px: medians 0.057 / 0.057 mm
   horizontal); `SIGMA_ALONG` 6 / 10 / 15 px gave horizontal medians 0.059 / 0.051 / 0.048 mm, p95
   0.22 / 0.24 / 0.34 mm, and vertical gross 0.24 / 1.3 / 3.7 %: longer smoothing rounds the
   bead's corners, so 6 px. A stripe turned ≥ `orient.MIN_DEG` from its axis (a rolled cross)
   is smoothed along its measured direction instead and linked by its offsets from it; the
   path's pieces along the other stripe and its ends' tails below half the plateau strength
   are dropped (`orient`, `ORIENT`). The default rig's stripes (< 7°) are untouched.
4. Linking (`cslx.segmentation.ridges.linked_centres`): K candidates per column, Viterbi
   path, outliers and short detours dropped, predicted standard deviation per centre; short
   pieces far off the path across a gap (`ridges.drop_stray`) dropped before and after step 5.
5. Bridging (`_bridge`): where the other stripe's core is clipped across the whole column
   (a run longer than `MAX_RUN`, left unfilled), nothing of this stripe can be measured; the
   path there and `BRIDGE_MARGIN` px around it is replaced by the line through
   `BRIDGE_SUPPORT` path points on each side (gaps up to `MAX_BRIDGE`), flagged `saturated`,
   with the line's prediction std as `sigma`. Gaps with no clipped pixels (the laser's shadow
   behind a bead, black print) are not bridged.
6. Path smoothing (`cslx.segmentation.path.smooth_path`): local quadratics along the path
   with a window per centre by the ICI rule, so plates average many speckle grains and
   corners stay sharp; within 1.5 `SIGMA_ALONG` of the image border (where the mirrored
   smoothing along the stripe bends a tilted stripe by up to 1.4 px) the centres take the
   value of the fit through the interior ones (their `sigma` raised by the extrapolation).

Evidence (`experiments/robust_extraction.py`, 2 frames × 18 conditions — the four presets,
green and blue lasers, saturated cores with and without sun, a thin stripe on a printed
target — at held-out seeds 9100–9117; development used 7100–7117). Horizontal / vertical
stripe, pooled: the linked detector of the first version (2-D Hessian candidates, σ 3.5)
found 99.20 / 99.22 % of the ground-truth columns / rows with 0.36 / 0.59 % gross (> 1 mm)
centres, median 0.066 / 0.082 mm, p95 0.277 / 0.385 mm; the column-profile version without
the path smoothing and the reflectance division 100.00 / 99.81 %, 0.07 / 0.27 % gross (all
vertical gross from the printed target: 2.38 %, median 0.36 mm), median 0.060 / 0.088 mm,
p95 0.214 / 0.459 mm; this version (commit 0ee39e6) finds 100.00 / 99.97 % with
0.00 / 0.01 % gross, median 0.040 / 0.052 mm, p95 0.190 / 0.225 mm (printed target vertical:
100 %, 0.00 % gross, median 0.068 mm). The old default (MED + Steger, R−G, σ 2): 86.50 /
89.59 %, 41.30 / 42.90 % gross, medians 0.254 / 0.329 mm. MED in front of linked (horizontal
stripe) makes the median worse (0.061 mm pooled) and breaks saturated cores, so MED is not
part of it; the paper's MED + Steger stays as method "med" (Table 6). Flat wall, no bead in
view (`experiments/flat_wall.py`, saturated stripes with and without sun, seeds 51–54 held
out; 41–42 were used in development): undistorted centres scatter 0.030–0.049 px RMS about a
straight line horizontally, 0.020–0.072 px vertically (one of 8 above 0.07), largest
distance 0.37 px; MED + Steger 0.12–63 px.

Missed goals of issue 11: median ≤ 0.03 mm and p95 ≤ 0.1 mm. Where the error lies
(development frames, seeds 7100–7117, 2 frames × 18 conditions, before the second pass,
H / V): plate columns (≈ 79 % of the centres) median 0.034 / 0.041 mm, p95 0.129 / 0.147;
bead cap 0.097 / 0.100, p95 0.29 / 0.44; ±8 px around the bead's corners (2–4 %) 0.18 / 0.20,
p95 0.51 / 0.58; the crossing 0.045 / 0.040; the outer 12 columns 0.072 / 0.121. The same
frames rendered without speckle: median 0.020 / 0.025 mm, p95 0.133 / 0.149; without
speckle and sensor noise: 0.018 / 0.026, p95 0.140 / 0.179 (bead 0.066 / 0.059, corners
0.117 / 0.134). So the median is set by speckle (0.020 → 0.039 mm H), the p95 by biases that
no noise reduction removes: the corners and the bead cap (the smoothing along the image axis
bends a curved path towards its chord), sunlit backgrounds under the profile, and the border.
An oracle that measures each column of the noise-free laser-only image (the frame minus
the same frame with the laser off) around the true row with σ 2.5 px and no smoothing
along the stripe scores, on the clean scenes, median 0.020 / 0.030 mm and p95 0.068 /
0.092 mm (sampling bias of a ≈ 1 px wide profile, which smoothing along a tilted stripe
averages out): the goal's median is near that floor even without speckle.
7. Second pass (`refine.second_pass`): the centres are re-measured around
   the smoothed path, with the smoothing (`SIGMA_REFINE`) along the path instead of the
   image axis, then smoothed again. Development frames, H / V: p95 0.190 / 0.224 →
   0.173 / 0.198 mm (corners median 0.176 / 0.201 → 0.136 / 0.168 mm, bead 0.097 / 0.100 →
   0.083 / 0.092, border p95 0.270 / 0.492 → 0.187 / 0.330), median 0.039 / 0.046 mm
   unchanged, detection unchanged (100 / 99.90 %), gross 0.00 / 0.07 → 0.01 / 0.08 % (one
   and two centres; sunny vertical 0.42 → 0.73 %, glare vertical 0.16 → 0 %). Without
   speckle and noise p95 0.140 / 0.179 → 0.120 / 0.140 mm (σ 4 px along the path). Flat wall
   (development seeds 41–46, saturated with and without sun): RMS 0.025–0.059 / 0.029–0.069
   px against 0.029–0.059 / 0.028–0.068 px before, none above 0.07. Cost: the pass alone
   2.2 ms per stripe (load 6.6); a whole frame and stripe (sunny, H / V, same run, load 13)
   51.5 / 55.8 → 57.7 / 58.7 ms.
   The pass runs on the monochrome image divided by the reflectance on every frame
   (`REFINE_REFLECTANCE`, `_reflectance_divided`; the first pass keeps the printed-target
   gate). Development frames (same 36 frames, H / V): median 0.039 / 0.046 → 0.038 / 0.043 mm,
   p95 0.173 / 0.198 → 0.169 / 0.191 mm, gross 0.01 / 0.08 → 0.00 / 0.07 %, detection
   unchanged (clean 0.053 / 0.053 → 0.048 / 0.049 mm; a few conditions lose ≤ 0.002 mm:
   blue V median, blue and saturated-sunny H p95, shadow V p95). Floors 0.5 / 1 / 3 instead
   of 0.3: medians 0.038 / 0.044, 0.039 / 0.046, 0.040 / 0.048 mm. Tried on the second pass
   and dropped (same frames, H / V median, p95 mm): σ across 1.5 / 2 / 3.5 px (0.049 / 0.056,
   0.044 / 0.050, 0.040 / 0.045 with p95 0.184 / 0.197); the along-path Gaussian's length
   chosen per centre by the ICI rule from 2–32 px (0.038 / 0.044 but corners 0.18 → 0.24 /
   0.19 → 0.30, p95 0.185 / 0.206); re-centring on the along-path mean of the first path
   (V p95 0.298); subtracting the line through the profile's outer taps (H median 0.039, p95
   0.167). Speckle remains the limit: the clean development frames re-rendered without
   speckle score median 0.006–0.016 mm, p95 0.040–0.072 mm (4 frames); without texture,
   about as with it. Flat wall (seeds 41–46): RMS 0.025–0.059 / 0.029–0.069 →
   0.027–0.056 / 0.027–0.069 px (mean 0.045 → 0.043), largest distance 0.250 → 0.242 px.
   Cost (sunny and clean frames, same run, load 15.8): 75.7 / 79.9 → 79.5 / 85.3 ms per
   frame and stripe.
   The final smoothing of the second pass also fits one-sided windows (a centre next to a
   bead corner averages the plate on its own side) up to ±256 centres with c = 6
   (`refine.second_pass` has the variants). Development frames (same 36 frames, H / V):
   median 0.038 / 0.043 → 0.035 / 0.039 mm, p95 0.169 / 0.191 → 0.153 / 0.169 mm (pixel
   error medians: corners 0.137 → 0.094, border 0.072 → 0.053, plate 0.033 → 0.030, bead
   0.080 → 0.076 px), detection unchanged, gross 0.004 / 0.070 → 0.026 / 0.075 %. Flat wall
   (seeds 41–46): RMS 0.027–0.069 → 0.019–0.066 px (mean 0.043 → 0.037), largest distance
   0.242 → 0.241 px. Cost: the smoothing 1.0 → 3.7 ms per stripe (load 11; whole frames
   under that load scattered 47–133 ms per frame and stripe, before and after alike).
   Where they hold, speckle-weighted profile fits (offsets from the path) replace its centres.
   The final smoothing is run again with each centre weighted by its local precision
   (`refine.LOCAL_WEIGHTS`): development frames (36), H / V median / p95 0.0300 / 0.1347,
   0.0313 / 0.1438 → 0.0297 / 0.1336, 0.0312 / 0.1398 mm; fresh frame 2 (18) 0.0290 /
   0.1397, 0.0358 / 0.1517 → 0.0283 / 0.1346, 0.0346 / 0.1495; +4–5 ms per stripe.
   A saturated path on a chroma-subsampled frame (JPEG, YUYV) is also re-measured on the
   luma, the two averaged (`CHROMA_REFINE`); 4:2:2 widens the clip test (all in `chroma`).
   Centres beside a turned cross's crossing or cut by the border are interpolated, those on
   the border dropped in step 5 (`crossing`, `CROSSING`, `EDGE_DROP`), and so is the first
   pass's tail past a turned stripe's end inside the frame (`ends`, `END_TRIM`).
8. No stripe (`cslx.segmentation.presence`): a path with median `sigma` > 0.4 px or median
   strength < 18 × the ridge noise is dropped whole (laser off in sun: the bead's sheen gave
   up to 616 "centres" per stripe), unless it is a faint stripe with a precise, long path
   (σ ≤ 0.33 px, strength ≥ 12, over half the columns) or a strong one (strength ≥ 60,
   σ ≤ 1.5 px: a turned cross's first pass is rough); no laser-on development frame
   changes (bit-identical).
9. The border (`cslx.segmentation.border`, `BORDER`): a turned stripe's ends that leave the
   frame across the search axis are set by a line through the centres further inside, up to
   the border, while the image there is lit and agrees with the line (a rolled cross lost
   4–16 centres a frame and stripe there); aligned stripes are untouched (development
   benchmark bit-identical).
Cost per frame and stripe: results/robust_extraction.md (the old default's in the same run).
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from ..config import CLIP_LEVEL, SIGMA_MAX
from . import border, chroma, crossing, ends, orient, presence
from .clipped import MAX_RUN, clipped_mask, fill_clipped, white_mask
from .path import smooth_path
from .refine import second_pass
from .ridges import (
    PATH_HALF_WINDOW,
    LinkParams,
    _median,
    _path_scatter,
    drop_stray,
    linked_centres,
)
from .search import _unclipped_space, search_space_unclipped
from .steger import Centres

__all__ = ["CLIP_LEVEL", "MAX_RUN", "SIGMA0", "SIGMA_MIN", "SIGMA_PER_WIDTH", "clipped_mask",
           "fill_clipped", "white_mask", "linked_extract", "max_run_for",
           "search_space_unclipped", "stripe_sigma"]  # fmt: skip

#: Floor, slope and ceiling of the width-aware σ. Steger's condition is σ ≥ s (Gaussian
#: profile of std s); on the development frames (seeds 7100–7117, all conditions) a fixed σ of
#: 2.5 / 3.5 / 4.5 px gave median errors 0.090 / 0.084 / 0.073 mm at the same detection and
#: gross rates, so σ goes to twice the measured s, at least 3.5 px.
SIGMA_MIN = 2.5
#: σ of the first (width-measuring) pass, px: the floor, so that pass is final on most frames.
SIGMA0 = SIGMA_MIN
SIGMA_PER_WIDTH = 1.0
#: Smoothing along the stripe (px) of the column-profile candidates.
SIGMA_ALONG = 6.0
#: σ ceiling (px) up to 480 px frames; above, ×min(H, W)/480 (the stripe's width in px grows
#: with magnification). Rig audit (1280×720, 2× focal length, 4 mm sheet, s ≈ 9.5 px, dev
#: seeds 8800–8801): σ 6 / 9 / 12 gave H gross 54 / 5 / 5 and V 55 / 20 / 21 centres.
#: (`cslx.config.SIGMA_MAX`, shared with the tracker's `cslx.runtime.stripe_width`.)
#: Frame height (px) up to which `SIGMA_MAX` applies unscaled.
SIGMA_MAX_HEIGHT = 480
#: Smooth the linked path with adaptive local quadratics (`cslx.segmentation.path`).
SMOOTH_PATH = True


def stripe_sigma(width_px, height: int | None = None) -> float:
    """Width-aware Steger σ from the profile std s (px; module docstring, step 3); `height`
    is the frame's smaller side, which scales the ceiling `SIGMA_MAX` above 480 px."""
    w = np.asarray(width_px, float)
    w = w[np.isfinite(w)]
    if len(w) < 8:
        return SIGMA_MIN
    s = float(np.median(w))
    ceiling = SIGMA_MAX * max(1.0, (height or 0) / SIGMA_MAX_HEIGHT)
    return float(np.clip(round(2 * SIGMA_PER_WIDTH * s) / 2, SIGMA_MIN, ceiling))


def max_run_for(shape) -> int:
    """`MAX_RUN` scaled like the σ ceiling (`SIGMA_MAX`): a 1280×720 rig at twice the focal
    length sees saturated cores of 30+ px (dev seeds 8800–8801: detection H / V 97.5 / 91.2
    → 100 / 99.9 %)."""
    return int(round(MAX_RUN * max(1.0, min(shape) / SIGMA_MAX_HEIGHT)))


@functools.partial(jax.jit, static_argnames=("axis", "auto", "divide", "pairs"))
def _prepare(image, clip_level, weights, *, axis: int, auto: bool, divide: bool = True, pairs=()):
    """Monochrome image with clipped runs filled, the filled mask, the clipped-and-unfilled
    mask, the weights used (`weights`, or the clip-aware kurtosis search's when `auto`) and
    the second pass's monochrome image (divided by the reflectance when `divide`)."""
    clipped = chroma.clipped_pairs(image, clip_level, axis=axis, margins=pairs)
    w = _unclipped_space(image, clipped, axis) if auto else weights.astype(image.dtype)
    raw = image @ w
    run = max_run_for(image.shape[:2])
    mono, filled = fill_clipped(
        _reflectance_normalised(image, raw), clipped, axis=axis, max_run=run
    )
    if divide:
        divided = _reflectance_divided(image, raw, clipped)
        second, _ = fill_clipped(divided, clipped, axis=axis, max_run=run)
    else:
        second = mono
    return mono, filled, clipped & ~filled, w, second


#: A frame is a printed / textured target when this share of its neighbouring pixel pairs
#: differ by more than `EDGE_STEP` × the median in the darkest channel (development frames:
#: printed targets 0.066–0.112, every other condition ≤ 0.016).
TEXTURE_EDGES = 0.03
EDGE_STEP = 0.4
#: Regulariser of the reflectance division, in units of the darkest channel's median.
REFLECTANCE_FLOOR = 0.3


def _reflectance_normalised(image, mono):
    """`mono` divided by the surface reflectance where the frame is a printed target.

    The laser's signal is reflectance × laser power, so where the stripe runs along the edge
    of a printed square, the black half of the profile is missing and the centre moves
    towards the white side; no colour space removes that (the print is grey and cancels,
    but it multiplies the laser). The darkest channel (the one with least laser light) is
    reflectance × ambient; dividing by it, regularised by `REFLECTANCE_FLOOR` × its median
    c, gives mono · (median + c) / (darkest + c). Ambient steps (shadow, sunlit sheen) do not
    multiply the laser, so the division is applied only to frames with many sharp
    reflectance steps (`TEXTURE_EDGES`). Development frames (seeds 7100–7117): printed
    target horizontal / vertical median 0.069 / 0.105 → 0.048 / 0.047 mm, gross 0.00 / 0.11
    → 0.00 / 0.00 %, detection 98.95 / 98.85 → 100 / 100 %; applied to every frame it cost
    detection in sun and shadow (vertical 99.3 %), hence the gate.
    """
    dark, med, c = _darkest(image)
    step = EDGE_STEP * med
    edges = 0.5 * (
        jnp.mean(jnp.abs(jnp.diff(dark, axis=0)) > step)
        + jnp.mean(jnp.abs(jnp.diff(dark, axis=1)) > step)
    )
    return jnp.where(edges > TEXTURE_EDGES, mono * (med + c) / (dark + c), mono)


def _darkest(image):
    """The darkest channel (reflectance × ambient), its median c̃ (every 4th pixel) and the
    regularising floor c = `REFLECTANCE_FLOOR` · c̃ + 1 of the reflectance divisions."""
    dark = jnp.min(image, axis=-1)
    med = _median(dark[::4, ::4].reshape(-1))
    return dark, med, REFLECTANCE_FLOOR * med + 1.0


#: The second pass (step 7) re-measures the centres on the monochrome image divided by the
#: reflectance (`_reflectance_divided`) on every frame, not only on printed targets.
REFINE_REFLECTANCE = True


def _reflectance_divided(image, mono, clipped):
    """`mono` · (c̃ + c) / (darkest + c) on every frame, for the second pass (step 7).

    The same division as `_reflectance_normalised` (c = `REFLECTANCE_FLOOR` × the darkest
    channel's median c̃), without the printed-target gate, and with clipped pixels (whose
    darkest channel is the laser's white core, not the surface) divided by the median. The
    first pass keeps the gate: dividing by ambient steps (shadow edges, sunlit sheen) cost
    it detection. Once the path is found, the division only reshapes the profile under it:
    a reflectance or shading slope across the stripe, which moves a centre, is flattened.
    Development frames: see the module docstring, step 7.
    """
    dark, med, c = _darkest(image)
    dark = jnp.where(clipped, med, dark)
    return mono * (med + c) / (dark + c)


def linked_extract(
    image,
    *,
    space="auto",
    stripe: str = "h",
    sigma: float | None = None,
    clip_level: float = CLIP_LEVEL,
    k: int = 4,
    params: LinkParams = LinkParams(),
    stripe_deg: float | None = None,
) -> Centres:
    """Centres of one stripe by the robust method (module docstring).

    Args:
        image: (H, W, 3) RGB frame (8-bit scale for the clipping test; a uint16 frame, as
            a 16-bit file holds it, is brought to that scale by / 257) or (H, W) monochrome.
        space: colour space ("auto": clip-aware kurtosis search; a name or weights).
        stripe: "h" or "v".
        sigma: fixed Steger scale (px); None chooses it from the measured width.
        clip_level: channel value treated as clipped (RGB input only).
        k: candidate ridges per column/row.
        params: the path cost weights (`LinkParams`).
        stripe_deg: the calibration's angle of this stripe in search orientation
            (`orient.plane_angle`): which of a turned cross's stripes is this one; None: the
            rule of `orient.peak_angles`.

    Returns:
        `Centres` with `sigma` (predicted std, px) and `saturated` flags.
    """
    from .colour import parse_space
    from .interface import _axis, monochrome_for

    axis = _axis(stripe)
    image = jnp.asarray(image)
    if image.ndim == 3 and image.shape[-1] == 3:
        if not jnp.issubdtype(image.dtype, jnp.floating):
            wide = image.dtype == jnp.uint16  # else every pixel would count as clipped
            image = image.astype(jnp.result_type(float))
            image = image / 257.0 if wide else image
        weights = parse_space(space) if isinstance(space, str) else space
        auto = isinstance(weights, str)
        weights = np.zeros(3) if auto else np.asarray(weights, float)
        sub, pairs = chroma.formats(image, axis) if CHROMA_REFINE else (False, False)
        mono, filled, blind, w, mono2 = _prepare(
            image,
            clip_level,
            jnp.asarray(weights, image.dtype),
            axis=axis,
            auto=auto,
            divide=REFINE_REFLECTANCE,
            pairs=chroma.pair_margins() if pairs else (),
        )
    else:
        mono, _ = monochrome_for(image, space, stripe)
        mono2, sub, pairs = mono, False, False
        filled = jnp.zeros(mono.shape, bool)
        blind = filled
    sa = SIGMA_ALONG
    first = SIGMA0 if sigma is None else float(sigma)
    final = first
    # a stripe turned far from its axis: smoothed and linked along it (`orient`)
    slope, other = (
        orient.search_slope(mono if axis == 0 else mono.T, 1 - 2 * axis, stripe_deg)
        if ORIENT
        else (None, None)
    )
    kw = dict(axis=axis, k=k, params=params, sigma_along=sa, slope=slope)
    if slope is not None:  # computed once for both passes
        kw["along"] = orient.smooth_along(mono.T if axis == 0 else mono, slope, sigma=sa)
    c, width = linked_centres(mono, sigma=first, **kw)
    width_final = width
    if sigma is None:
        # The first pass at the floor σ is final unless the measured width asks for more.
        final = stripe_sigma(width, min(mono.shape))
        if final != first:
            c, width_final = linked_centres(mono, sigma=final, **kw)
    if slope is not None and DROP_OTHER:
        v = orient.drop_other(c.pos, c.valid, slope, other)
        v = jnp.asarray(orient.trim_ends(v, c.strength) if TRIM_ENDS else v)
        c = c._replace(pos=jnp.where(v, c.pos, jnp.nan), valid=v)
    pos, valid, sig, sat, bridged = _finish(
        c.pos, c.valid, c.sigma, filled, blind, axis=axis, trim=END_TRIM
    )
    signals = [(mono2, 1.0)]
    if sub and not pairs and chroma.saturated_share(sat, valid) >= CHROMA_SATURATED:
        kw = dict(axis=axis, variant=CHROMA_REFINE, max_run=max_run_for(image.shape[:2]))
        luma = chroma.second_signal(image, w, clip_level, **kw)
        signals = [(mono2, 1.0 - CHROMA_BLEND), (luma, CHROMA_BLEND)][CHROMA_BLEND == 1 :]
    if REFINE:
        unusable = filled | blind
        first_pos, pos = pos, 0.0
        cross = None
        if CROSSING:  # σ_t of the smoothed profile (no width measured: σ)
            w = np.asarray(width)[np.isfinite(np.asarray(width))]
            t = math.hypot(final, float(np.median(w)) if w.size else 0.0)
            cross = crossing.interpolated(mono2, first_pos, valid & ~bridged, t, axis=axis)
        for m2, weight in signals:
            p = first_pos
            for s_along in REFINE_PASSES:  # one pass by default (REFINE_PASSES)
                p = second_pass(
                    m2, p, valid, bridged, unusable, sigma=final, axis=axis, sigma_along=s_along,
                    interpolate=cross)  # fmt: skip
            pos = pos + weight * p if len(signals) > 1 else p
    if presence.NO_STRIPE_SIGMA is not None:  # step 8
        pos, valid, sig, sat = presence.absent(pos, valid, sig, c.strength, sat)
    strength = c.strength
    if BORDER:  # step 9
        w = np.asarray(width_final)[np.isfinite(np.asarray(width_final))]
        t = math.hypot(final, float(np.median(w)) if w.size else 0.0)
        pos, valid, sig, strength = border.extend(pos, valid, sig, strength, mono2, blind, t, axis)
    return c._replace(
        pos=pos, valid=valid, sigma=sig, strength=jnp.where(valid, strength, 0.0), saturated=sat
    )


@functools.partial(jax.jit, static_argnames=("axis", "trim"))
def _finish(pos, valid, sigma, filled, blind, *, axis: int, trim: bool = False):
    """Path smoothing (`cslx.segmentation.path`), bridging (`_bridge`) and the `saturated`
    flags, in one compiled call; `trim`: the tail past a turned stripe's end (`ends`)."""
    f = filled if axis == 0 else filled.T
    b = blind if axis == 0 else blind.T
    valid = drop_stray(jnp.nan_to_num(pos), valid)
    if EDGE_DROP:
        valid = valid & crossing.inside(pos, f.shape[0])
    if trim:
        valid = ends.oblique_ends(jnp.nan_to_num(pos), valid, f.shape[0])
    pos, valid, sig, bridged = _bridge(pos, valid, sigma, b)
    # a piece left at an end once the bridging dropped what was behind it
    valid = drop_stray(jnp.nan_to_num(pos), valid)
    pos = jnp.where(valid, pos, jnp.nan)
    if SMOOTH_PATH:
        scatter = _path_scatter(jnp.nan_to_num(pos), valid, 2 * PATH_HALF_WINDOW)
        # Within 2 SIGMA_ALONG of the image border the smoothing along the stripe mirrors
        # the image (a tilted stripe bends towards the border's normal there): those
        # centres take the value of the fit through the interior ones.
        j = jnp.arange(pos.shape[0])
        edge = int(round(1.5 * SIGMA_ALONG))
        inside = (j >= edge) & (j < pos.shape[0] - edge)
        smoothed, factor = smooth_path(jnp.nan_to_num(pos), valid, scatter, support=inside)
        pos = jnp.where(valid, smoothed, pos)
        # The fit's white-noise factor (≈ 0.2 on plates) would make `sigma` 3× too small
        # against the development frames' errors (median |error| / σ 0.82 / 0.75 before
        # smoothing, H / V, 1.99 / 1.66 after scaling by it): the residual error is
        # correlated speckle and corner bias, which averaging reduces far less (medians
        # × 0.68 / 0.52). `sigma` is kept (median |error| / σ 0.54 / 0.42 after smoothing,
        # 8.6 / 4.2 % beyond 2σ), and raised where a border centre is extrapolated.
        sig = jnp.where(valid, sig * jnp.maximum(factor, 1.0), sig)
    near = jnp.clip(jnp.round(jnp.nan_to_num(pos)).astype(jnp.int32), 0, f.shape[0] - 1)
    sat = (f[near, jnp.arange(f.shape[1])] & valid) | bridged
    return pos, valid, sig, sat, bridged


#: Re-measure the centres along the smoothed path (`cslx.segmentation.refine`), step 7.
REFINE = True
#: Interpolate centres at a turned crossing or cut by the border; drop border ones (`crossing`).
CROSSING = EDGE_DROP = True
#: Set a turned stripe's centres near the border it leaves the frame by from a fit through
#: those inside (`border`), step 9. Its first form (a quadratic) added gross (> 1 mm)
#: centres (held out 33, 18 and 15 on three sets of 20 frames); the line with the check
#: against the image along the border (branch border11b) adds none on the fresh held-out set
#: (seeds 7870–7874, frames 0–3) and recovers 0.6–4.4 % of the rows and columns there (every
#: condition rises; `experiments/ood_extraction.py`); issue 11 counts a gross centre as worse
#: than a missing one. The development benchmark (18 conditions, 7100–7117) is bit-identical.
BORDER = True
#: Drop the first pass's tail past a turned stripe's end inside the frame (`ends`), step 5.
END_TRIM = True
#: Smooth and link a stripe turned ≥ `orient.MIN_DEG` from its axis along it (`orient`), step 3.
ORIENT = True
#: With `ORIENT`, drop the pieces of the first path that run along the other stripe.
DROP_OTHER = True
#: With `ORIENT`, cut the path's ends where the strength falls below half its plateau.
TRIM_ENDS = True
#: Step 7 on a chroma-subsampled frame (`chroma.subsampled`: JPEG, YUYV; never a rendered
#: one) whose path is at least `CHROMA_SATURATED` saturated runs on this signal as well
#: (`chroma.second_signal`; None: off), its centres weighted `CHROMA_BLEND` against the colour
#: space's. Evidence: `cslx.segmentation.chroma`.
CHROMA_REFINE = "luma"
CHROMA_SATURATED = 0.5
CHROMA_BLEND = 0.5
#: Along-path σ (px) of each re-measurement of step 7, in order; None is
#: `refine.SIGMA_REFINE`. One pass by default. Why more were tried (issue 11, the toes):
#: `refine_centres` returns p + G∗(c − p) for a reference path p, so its error is
#: −(I − G)(c − p): a first-pass error narrower than G — the bead toes' rounding by the 6 px
#: smoothing along the image axis, a kink of slope change 0.2 rounded by ≈ 0.2·6/√(2π) ≈
#: 0.5 px — passes almost whole (`tests/segmentation/test_refine.py`: 0.119 → 0.111 px at a
#: bend with G 6 px, 0.052 px with G 2 px). A second pass around the first's output, a short
#: G first, attacks that. Development frames (seeds 7100–7117, frames 0–1, 36 frames; H / V
#: median / p95 mm, detection 100 / 99.90 % throughout) — one pass (default): 0.0300 /
#: 0.135, 0.0313 / 0.144, gross 0.02 / 0.06 %; (6, 6): 0.0299 / 0.131, 0.0311 / 0.144,
#: gross 0.03 / 0.08 %; (2, 6): 0.0300 / 0.131, 0.0308 / 0.145, gross 0.06 / 0.06 % (toes
#: p95 0.347 / 0.322 → 0.283 / 0.278 mm but caps H 0.249 → 0.334: the short pass follows
#: glints on the bead); (2, 6) with the short pass's path used only where it leaves the
#: first pass's by > 3 robust std: 0.0298 / 0.132, 0.0309 / 0.143, gross 0.06 / 0.06 %;
#: (3, 6): 0.0297 / 0.128, 0.0308 / 0.143, gross 0.03 / 0.06 % (V sunny p95 0.249 → 0.225,
#: H clean median 0.025 → 0.026). On fresh development frames (frame 2, 18 frames), (3, 6)
#: against one pass: H 0.0290 / 0.140 → 0.0297 / 0.137, V 0.0358 / 0.152 → 0.0358 / 0.149,
#: V gross 0 → 0.05 % (printed). A 2 % gain in the p95 with a worse H median, more gross
#: centres and one more second pass (its profile fit ≈ 15 ms per frame and stripe), so
#: the default stays one pass. A smaller σ in the only pass (`SIGMA_REFINE` 4): 0.0314 /
#: 0.138, 0.0308 / 0.150; `SIGMA_ALONG` 4 in the first pass: 0.0299 / 0.136, 0.0311 /
#: 0.142, H detection 99.97 %.
REFINE_PASSES = (None,)


#: Longest stretch (px) of a stripe hidden by clipped pixels that is bridged.
MAX_BRIDGE = 40
#: Columns next to hidden ones whose centres are replaced too (the smoothing along the
#: stripe mixes the hidden pixels into them).
BRIDGE_MARGIN = 6
#: Path points on either side that carry the bridge's line.
BRIDGE_SUPPORT = 12


@jax.jit
def _bridge(pos, valid, sigma, blind):
    """Centres across a stretch of the stripe hidden by unfillable clipped pixels.

    Where the other stripe's clipped core crosses (a run longer than `MAX_RUN` along the
    search axis), nothing of this stripe can be measured. Centres on or within
    `BRIDGE_MARGIN` of such columns are replaced, over a gap of at most `MAX_BRIDGE`, by the
    least-squares line through `BRIDGE_SUPPORT` path points on each side; they are flagged
    (`saturated`) and their σ is the line's prediction std plus the path's scatter.

    Args: pos, valid, sigma (N,) of the linked path; blind (H', N) clipped-and-unfilled mask
    in search orientation. Returns (pos, valid, sigma, bridged).
    """
    n = pos.shape[0]
    n_along = blind.shape[0]
    j = jnp.arange(n)
    prev = lax.cummax(jnp.where(valid, j, -1))
    nxt = lax.cummin(jnp.where(valid, j, n), reverse=True)
    pp, nn = jnp.clip(prev, 0, n - 1), jnp.clip(nxt, 0, n - 1)
    span = jnp.maximum(nn - pp, 1).astype(pos.dtype)
    guess = jnp.where(valid, pos, pos[pp] + (j - pp) * (pos[nn] - pos[pp]) / span)
    guess = jnp.nan_to_num(guess)
    rows = jnp.clip(
        jnp.round(guess).astype(jnp.int32)[None, :] + jnp.arange(-3, 4)[:, None], 0, n_along - 1
    )
    hidden = jnp.any(blind[rows, j[None, :]], axis=0) & ((prev >= 0) | valid) & ((nxt < n) | valid)
    m = BRIDGE_MARGIN
    near = jnp.convolve(hidden.astype(pos.dtype), jnp.ones(2 * m + 1, pos.dtype), mode="same") > 0
    keep = valid & ~near
    prev = lax.cummax(jnp.where(keep, j, -1))
    nxt = lax.cummin(jnp.where(keep, j, n), reverse=True)
    gap = ~keep & (prev >= 0) & (nxt < n) & (nxt - prev - 1 <= MAX_BRIDGE)
    # the gap must contain hidden columns
    ch = jnp.concatenate([jnp.zeros(1, jnp.int32), jnp.cumsum(hidden.astype(jnp.int32))])
    has = ch[jnp.clip(nxt, 0, n)] - ch[jnp.clip(prev + 1, 0, n)] > 0
    gap = gap & has & near
    h = BRIDGE_SUPPORT
    off = jnp.arange(h)
    idx = jnp.concatenate([prev[:, None] - off[None, :], nxt[:, None] + off[None, :]], 1)
    ok = (idx >= 0) & (idx < n)
    idx = jnp.clip(idx, 0, n - 1)
    ok = ok & keep[idx]
    w = ok.astype(pos.dtype)
    x = (idx - j[:, None]).astype(pos.dtype)
    y = jnp.where(ok, pos[idx], 0.0)
    sw, sx, sxx = w.sum(1), (w * x).sum(1), (w * x * x).sum(1)
    sy, sxy = (w * y).sum(1), (w * x * y).sum(1)
    det = sw * sxx - sx * sx
    good = gap & (sw >= 6) & (det > 1e-6)
    safe = jnp.where(good, det, 1.0)
    a = (sxx * sy - sx * sxy) / safe
    b = (sw * sxy - sx * sy) / safe
    resid = jnp.where(ok, y - a[:, None] - b[:, None] * x, 0.0)
    s2 = (resid**2).sum(1) / jnp.maximum(sw - 2, 1.0)
    var_a = s2 * sxx / safe
    bridged = good
    new_pos = jnp.where(bridged, a, jnp.where(keep, pos, jnp.nan))
    new_valid = keep | bridged
    new_sig = jnp.where(bridged, jnp.sqrt(var_a + s2), jnp.where(keep, sigma, jnp.nan))
    return new_pos, new_valid, new_sig, bridged
