"""The clip-aware kurtosis colour search of the linked detector (step 1 of `robust`).

Section 3.1's search (the 74-space grid of `cslx.segmentation.colour`, normalized form) on
the frame with its clipped pixels replaced by the frame's median colour, so that a white
core does not decide the space (`search_space_unclipped`), scored from the channels'
moments (`_grid_scores`) on every `SEARCH_STRIDE`-th column (row). Evidence for the search
itself: `cslx.segmentation.robust`, step 1.

Which pixels count as clipped here: every pixel the detector treats as clipped
(`clipped_mask`, any channel ≥ `CLIP_LEVEL`) and, for the search only, every pixel with a
channel ≥ `SEARCH_CLIP_LEVEL`. JPEG (quantisation and 4:2:0 chroma) leaves a saturated core
broken: in a q85 frame (fresh seed 7419, frame 1, the vertical stripe) R reads 251–255
across the core, so only some of its pixels reach the clip level, and the others keep a
near-white colour with G and B smeared from the neighbours. Those pixels decided the space:
(1, −2, 1), which makes the core a deep hole between two lobes, scored above R − G (71.2 /
70.2), and the linked path in it wandered between the lobes (median predicted σ 0.97 px,
0.38 px median error; the no-stripe test then dropped the whole stripe); R − G, R or
2R − G − B give 0.045–0.048 px on that frame. See `SEARCH_CLIP_LEVEL` for the evidence.
"""

from __future__ import annotations

import functools
import itertools
import math

import jax
import jax.numpy as jnp
import numpy as np

from .. import config as _config
from ..config import CLIP_LEVEL, SEARCH_STRIDE
from .clipped import clipped_mask
from .ridges import _median

__all__ = ["SEARCH_CLIP_LEVEL", "search_mask", "search_space_unclipped"]

#: For the colour search only, a pixel with a channel at or above this 8-bit level counts as
#: clipped as well (module docstring). None: `CLIP_LEVEL` alone. Evidence, `CLIP_LEVEL` alone
#: → 240. Development frames (seeds 7100–7117, frames 0–1, both stripes: 72 searches): the
#: same space every time, as on the flat walls (seeds 41–46, saturated with and without sun,
#: 24 searches), so both are unchanged bit for bit (225, or the
#: clipped mask dilated by 1 / 2 px, changed 4 / 4 / 19 of them). Generality audit
#: (`experiments/ood_extraction.py`, seed 7400, 2 frames; detection %, gross %, median / p95
#: mm), the frames whose space changed: JPEG q85 saturated + sun V 47.29, 1.10, 0.176 / 0.308
#: → 99.69, 0.00, 0.052 / 0.243 (H 99.69, 0.71, 0.066 / 0.292 → 99.69, 0.94, 0.063 /
#: 0.339); JPEG q95 saturated H 0.059 / 0.186 → 0.044 / 0.140, V 0.086 / 0.263 → 0.032 /
#: 0.190 (100 %, no gross either way; it had picked G − B-like spaces); JPEG q70 sunny H
#: (frame 0) 0.063 / 0.290 → 0.067 / 0.262; the corner-aimed rig, clean, H (frame 1) 0.0258
#: / 0.087 → 0.0272 / 0.088. The green / blue lasers, JPEG q70 saturated, the thin stripe on
#: 4 / 10 mm print, 1280×720 and the 20°-turned cross kept their spaces.
SEARCH_CLIP_LEVEL: float | None = _config.SEARCH_CLIP_LEVEL


def search_mask(image, clipped):
    """(H, W) pixels the colour search replaces: `clipped`, and where a channel of `image`
    (8-bit scale) reaches `SEARCH_CLIP_LEVEL`."""
    if SEARCH_CLIP_LEVEL is None:
        return clipped
    return clipped | clipped_mask(image, SEARCH_CLIP_LEVEL)


# Kurtosis of a colour space from the channels' moments. I − μ = w·d (d: the centred RGB of a
# column) makes Σ(I − μ)² a quadratic and Σ(I − μ)⁴ a quartic form in w, so the 74 spaces of
# the grid are scored from 6 + 15 moment sums per column instead of 74 monochrome images
# (2 s → a few ms per frame). The channels are first turned into an orthonormal luminance /
# chroma basis: a zero-sum space (R − G, 2R − G − B) then has no luminance term at all, and
# float32 does not lose it to cancellation against the (large) grey sunlight.
_BASIS = np.array([[1, 1, 1], [1, -1, 0], [1, 1, -2]], float)
_BASIS /= np.linalg.norm(_BASIS, axis=1, keepdims=True)
_PAIRS = list(itertools.combinations_with_replacement(range(3), 2))
_QUADS = list(itertools.combinations_with_replacement(range(3), 4))


def _form_coefficients(candidates: np.ndarray, powers) -> np.ndarray:
    """(K, P) coefficients of the monomials `powers` of w' = B w for every candidate w."""
    w = np.asarray(candidates, float) @ _BASIS.T
    out = np.empty((len(w), len(powers)))
    for j, p in enumerate(powers):
        counts = np.bincount(p, minlength=3)
        multinomial = math.factorial(len(p)) / np.prod([math.factorial(c) for c in counts])
        out[:, j] = multinomial * np.prod(w[:, list(p)], axis=1)
    return out


def _grid_scores(image, candidates: np.ndarray):
    """Normalized kurtosis score (`colour.kurtosis_objective`, axis 0) of every candidate."""
    x = image @ jnp.asarray(_BASIS.T, image.dtype)
    d = x - jnp.mean(x, axis=0)
    m = d.shape[0]
    s2 = jnp.stack([jnp.sum(d[..., a] * d[..., b], 0) for a, b in _PAIRS], -1)
    q = jnp.stack([d[..., a] * d[..., b] for a, b in _PAIRS], -1)
    s4 = jnp.stack(
        [
            jnp.sum(q[..., _PAIRS.index((a, b))] * q[..., _PAIRS.index((c, e))], 0)
            for a, b, c, e in _QUADS
        ],
        -1,
    )
    c2 = jnp.asarray(_form_coefficients(candidates, _PAIRS).T, image.dtype)
    u = s2 @ c2
    f = s4 @ jnp.asarray(_form_coefficients(candidates, _QUADS).T, image.dtype)
    # The flat-column guard of `colour.column_kurtosis`, plus one for spaces that are flat
    # only up to rounding: a space that cancels every varying channel (B alone beside a
    # constant G and B) gets u from cancelling terms of size Σ|c||s2|, i.e. rounding noise,
    # and f / u² of that noise scored highest. Such a column counts as flat (neutral).
    tiny = jnp.finfo(u.dtype).tiny ** 0.25
    rounding = 64 * jnp.finfo(u.dtype).eps * (jnp.abs(s2) @ jnp.abs(c2))
    ok = (u > tiny * jnp.maximum(jnp.max(u, axis=0), tiny)) & (u > rounding)
    u_safe = jnp.where(ok, u, 1.0)
    k = jnp.where(ok, f / (u_safe * u_safe), 3.0 / m)
    return jnp.mean(m * k - 3.0, axis=0)


def _unclipped_space(image, clipped, axis: int):
    """Weights (3,) of the clip-aware kurtosis search (section 3.1); traced, jit-safe."""
    from .colour import CANDIDATES, _skewness_sign

    flat = image.reshape(-1, 3)
    median = jnp.stack([_median(flat[::7, c]) for c in range(3)])
    img = jnp.where(search_mask(image, clipped)[..., None], median, image)
    # Every SEARCH_STRIDE-th column (row) is scored: the mean kurtosis over 160 of a frame's
    # 640 columns ranks the spaces as all of them do, at a quarter of the cost.
    seg = img if axis == 0 else jnp.swapaxes(img, 0, 1)
    scores = _grid_scores(seg[:, ::SEARCH_STRIDE], CANDIDATES)
    best = jnp.asarray(CANDIDATES, image.dtype)[jnp.argmax(scores)]
    return best * _skewness_sign(best, img, axis)


def search_space_unclipped(image, axis: int, clip_level: float = CLIP_LEVEL):
    """Kurtosis colour search (section 3.1) with clipped pixels set to the median colour.

    Same choice as `colour.search_space` (normalized form, the 74-space grid) on the frame
    with every clipped pixel replaced by the frame's median colour, scored from moments.
    """
    img = jnp.asarray(image)
    if not jnp.issubdtype(img.dtype, jnp.floating):
        img = img.astype(jnp.result_type(float))
    weights = _search_jit(img, clip_level, axis=axis)
    return tuple(float(w) for w in np.asarray(weights))


@functools.partial(jax.jit, static_argnames=("axis",))
def _search_jit(image, clip_level, *, axis):
    return _unclipped_space(image, clipped_mask(image, clip_level), axis)
