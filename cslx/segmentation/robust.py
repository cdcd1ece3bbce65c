"""Robust stripe extraction: colour space, clipped cores, width-aware σ, linked ridges.

The method "linked" of `cslx.segmentation.extract` (the default since issue 11):

1. Colour space. Fixed weights, or "auto": the kurtosis search of section 3.1
   (`cslx.segmentation.colour.search_space`) with clipped pixels replaced by the frame's
   median colour, so a white core does not decide the space (`search_space_unclipped`).
2. Clipped cores. A pixel with any channel at the sensor's maximum holds a lower bound, not
   a value. Along the search axis, every run of clipped pixels at most `max_run` long gets the
   constant 1.5 × max(value of its two unclipped neighbours) in the monochrome image
   (`fill_clipped`): a laser core clipped to a plateau (in R) or to a hole (in R − G, where
   R = G = B = 255 maps to 0) becomes one symmetric bump whose centre is the plateau's middle,
   set by its unclipped flanks. White glints have grey flanks (≈ 0 in a laser-coloured space)
   and stay dark. Centres on a filled run are flagged `saturated`.
3. σ from the width. A first pass at `SIGMA0` measures the stripe's profile standard
   deviation s on the linked path (Steger 1998 §4, `cslx.segmentation.ridges`); the final
   pass uses σ = `SIGMA_PER_WIDTH` × s rounded to 0.5 px within [`SIGMA_MIN`, `SIGMA_MAX`] —
   Steger's condition σ ≥ w/√3 for a bar of half-width w is σ ≥ s for a Gaussian profile, and
   a σ above it also averages speckle along the line.
4. Linking (`cslx.segmentation.ridges.linked_centres`): K candidate ridges per column,
   Viterbi path, Steger's sub-pixel step, predicted standard deviation per centre.

Why it is the default of `cslx extract` (results/robust_extraction.md: 18 conditions — the four
presets, green and blue lasers, saturated cores with and without sun, a thin stripe on a
printed target — one frame each at held-out seeds 9100–9117, straight and T scenes): pooled
over every condition the old default (MED + Steger, R−G, σ 2) finds 87 % / 88 % of the
columns / rows (horizontal / vertical stripe) with 41.5 % / 42.2 % gross (> 1 mm) centres and
medians 0.27 / 0.41 mm; "linked" finds 99.2 % / 99.2 % with 0.40 % / 0.63 % gross, medians
0.066 / 0.080 mm, p95 0.30 / 0.37 mm. On the four presets alone the old method has 0.6–2.9 %
gross, linked 0–0.23 %. MED in front of linked (the paper's order) made the median worse on
every preset and broke saturated cores (21.8 % gross pooled), so MED is not part of it; the
paper's MED + Steger stays as method "med" (Table 6). Missed goals of issue 11: gross ≤ 0.1 %
(saturated cores: 0.9–2.5 %, mostly at the crossing of two clipped stripes), detection
≥ 99.5 % (printed target 96.6–98.4 %, saturated in sun 95.7–97.7 %), median ≤ 0.03 mm
(0.045–0.155 mm) and p95 ≤ 0.1 mm (0.17–0.6 mm). Cost: 0.8–1.0 s per frame and stripe on the
shared 2-core CPU under load (two Hessian passes and the 74-space kurtosis search; the old
default took 69 / 115 ms).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .ridges import LinkParams, linked_centres
from .steger import Centres

__all__ = [
    "CLIP_LEVEL",
    "MAX_RUN",
    "SIGMA0",
    "SIGMA_MIN",
    "SIGMA_PER_WIDTH",
    "clipped_mask",
    "fill_clipped",
    "linked_extract",
    "search_space_unclipped",
    "stripe_sigma",
]

#: 8-bit value at and above which a channel is treated as clipped.
CLIP_LEVEL = 254.0
#: Longest clipped run (px along the search axis) treated as a saturated laser core.
MAX_RUN = 24
#: σ of the first (width-measuring) pass, px.
SIGMA0 = 2.5
#: Floor, slope and ceiling of the width-aware σ. Steger's condition is σ ≥ s (Gaussian
#: profile of std s); on the development frames (seeds 7100–7117, all conditions) a fixed σ of
#: 2.5 / 3.5 / 4.5 px gave median errors 0.090 / 0.084 / 0.073 mm at the same detection and
#: gross rates, so σ goes to twice the measured s, at least 3.5 px.
SIGMA_MIN = 3.5
SIGMA_PER_WIDTH = 2.0
SIGMA_MAX = 6.0


def clipped_mask(image, clip_level: float = CLIP_LEVEL):
    """(H, W) True where any channel of an 8-bit-scaled RGB frame is at `clip_level` or above."""
    image = jnp.asarray(image)
    return jnp.max(image, axis=-1) >= clip_level


@functools.partial(jax.jit, static_argnames=("axis", "max_run"))
def fill_clipped(mono, clipped, *, axis: int = 0, max_run: int = MAX_RUN):
    """Fill runs of clipped pixels along `axis` (≤ `max_run` long) from their flanks.

    Returns (filled image, (H, W) bool mask of the filled pixels). A run touching the image
    border or longer than `max_run` is left as it is.
    """
    m = mono if axis == 0 else mono.T
    c = clipped if axis == 0 else clipped.T
    n = m.shape[0]
    idx = jnp.arange(n)[:, None]
    above = lax.cummax(jnp.where(~c, idx, -1), axis=0)  # last unclipped index ≤ i
    below = lax.cummin(jnp.where(~c, idx, n), axis=0, reverse=True)  # first unclipped ≥ i
    length = below - above - 1
    inner = (above >= 0) & (below < n)
    run = c & inner & (length <= max_run)
    col = jnp.arange(m.shape[1])[None, :]
    fa = m[jnp.clip(above, 0, n - 1), col]
    fb = m[jnp.clip(below, 0, n - 1), col]
    level = 1.5 * jnp.maximum(jnp.maximum(fa, fb), 0.0)
    out = jnp.where(run, level, m)
    if axis == 1:
        out, run = out.T, run.T
    return out, run


def search_space_unclipped(image, axis: int, clip_level: float = CLIP_LEVEL):
    """Kurtosis colour search (section 3.1) with clipped pixels set to the median colour."""
    from .colour import search_space

    img = jnp.asarray(image)
    if not jnp.issubdtype(img.dtype, jnp.floating):
        img = img.astype(jnp.result_type(float))
    clipped = clipped_mask(img, clip_level)
    median = jnp.median(img.reshape(-1, 3), axis=0)
    img = jnp.where(clipped[..., None], median, img)
    weights, _ = search_space(img, axis=axis)
    return tuple(float(w) for w in np.asarray(weights))


def stripe_sigma(width_px) -> float:
    """Width-aware Steger scale from the measured profile std s (px): see the module docstring."""
    w = np.asarray(width_px, float)
    w = w[np.isfinite(w)]
    if len(w) < 8:
        return SIGMA0
    s = float(np.median(w))
    return float(np.clip(round(2 * SIGMA_PER_WIDTH * s) / 2, SIGMA_MIN, SIGMA_MAX))


def linked_extract(
    image,
    *,
    space="auto",
    stripe: str = "h",
    sigma: float | None = None,
    clip_level: float = CLIP_LEVEL,
    k: int = 4,
    params: LinkParams = LinkParams(),
) -> Centres:
    """Centres of one stripe by the robust method (module docstring).

    Args:
        image: (H, W, 3) RGB frame (8-bit scale for the clipping test) or (H, W) monochrome.
        space: colour space ("auto": clip-aware kurtosis search; a name or weights).
        stripe: "h" or "v".
        sigma: fixed Steger scale (px); None chooses it from the measured width.
        clip_level: channel value treated as clipped (RGB input only).
        k: candidate ridges per column/row.
        params: the path cost weights (`LinkParams`).

    Returns:
        `Centres` with `sigma` (predicted std, px) and `saturated` flags.
    """
    from .interface import _axis, monochrome_for

    axis = _axis(stripe)
    image = jnp.asarray(image)
    rgb = image.ndim == 3
    if rgb and isinstance(space, str) and space.strip().lower() == "auto":
        space = search_space_unclipped(image, axis, clip_level)
    mono, _ = monochrome_for(image, space, stripe)
    if rgb:
        mono, filled = fill_clipped(mono, clipped_mask(image, clip_level), axis=axis)
    else:
        filled = jnp.zeros(mono.shape, bool)
    if sigma is None:
        _, width = linked_centres(mono, sigma=SIGMA0, axis=axis, k=k, params=params)
        sigma = stripe_sigma(width)
    c, _ = linked_centres(mono, sigma=float(sigma), axis=axis, k=k, params=params)
    f = filled if axis == 0 else filled.T
    n_along = f.shape[0]
    near = jnp.clip(jnp.round(jnp.nan_to_num(c.pos)).astype(jnp.int32), 0, n_along - 1)
    sat = f[near, jnp.arange(f.shape[1])] & c.valid
    return c._replace(saturated=sat)
