"""One interface to every stripe segmentation method of Table 6.

`extract(image, method, space=..., stripe=...)` turns an RGB frame into per-column (horizontal
stripe) or per-row (vertical stripe) centres with any of `METHODS`:

- ``"cm"``, ``"la"``, ``"qa"``, ``"aa"``: the baselines of `cslx.segmentation.baselines`;
- ``"steger"``: Steger's detector (`cslx.segmentation.steger`) on the monochrome image, no MED;
- ``"med"``: the paper's full method (sections 3.1–3.3): MED along the stripe's search
  direction (`med.med`, delay-compensated output aligned with the image), then Steger.
- ``"linked"``: the robust detector of issue 11 (`cslx.segmentation.robust`): clip-aware colour
  search, clipped cores filled from their flanks, σ from the measured stripe width, candidate
  ridges linked into one continuous path (`cslx.segmentation.ridges`); its `Centres` carry a
  predicted standard deviation (`sigma`, px) and `saturated` flags. It is `cslx extract`'s
  default: the evidence (results/robust_extraction.md) is in `cslx.segmentation.robust`.

`centres_to_pixels` turns centres into OpenCV pixel coordinates (the centre-file contract of
docs/contracts.md); `cslx.segmentation.metrics` scores them against rendered ground truth.
"""

from __future__ import annotations

from typing import Any

import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from . import baselines
from .steger import Centres, steger_centres

__all__ = [
    "DEFAULT_SIGMA",
    "METHODS",
    "STRIPES",
    "centres_to_pixels",
    "extract",
    "monochrome_for",
]

METHODS = ("cm", "la", "qa", "aa", "steger", "med", "linked")
STRIPES = ("h", "v")
#: Steger scale for the rendered stripes (Gaussian sheet profile of ≈ 2 px std at 230 mm).
DEFAULT_SIGMA = 2.0
#: A 3-D error above this many mm is a gross outlier (docs/metrics.md.

_BASELINES = {"cm": baselines.cm, "la": baselines.la, "qa": baselines.qa, "aa": baselines.aa}


#: Smallest frame (px along / across the stripe) the linked detector accepts: its path
#: windows need ≥ 38 centres along the stripe and its K = 4 candidates 4 px across.
LINKED_MIN_ALONG = 40
LINKED_MIN_ACROSS = 8


def _axis(stripe: str) -> int:
    if stripe not in STRIPES:
        raise ValueError(f"stripe must be 'h' (horizontal) or 'v' (vertical), got {stripe!r}")
    return 0 if stripe == "h" else 1


def monochrome_for(image: ArrayLike, space: Any = "r-g", stripe: str = "h"):
    """The monochrome image of a frame in a colour space (section 3.1, eq. (8)).

    Args:
        image: (H, W, 3) RGB frame (uint8 or float), or an (H, W) frame already monochrome
            (returned unchanged as float; `space` is then ignored).
        space: a name or weights string for `colour.parse_space` ("r", "r-g", "gray",
            "W_R,W_G,W_B"), "auto" for the kurtosis search of the stripe's direction, or
            three weights.
        stripe: "h" or "v"; "auto" scores columns for "h" and rows for "v".

    Returns:
        ((H, W) float image, (3,) weights used or None for a monochrome input).
    """
    from .colour import monochrome, parse_space, search_space

    axis = _axis(stripe)
    image = jnp.asarray(image)
    if image.ndim == 2:
        if not jnp.issubdtype(image.dtype, jnp.floating):
            image = image.astype(jnp.result_type(float))
        return image, None
    if image.ndim != 3 or image.shape[-1] != 3:
        raise ValueError(
            f"expected an RGB image (H, W, 3) or a monochrome one (H, W), got {image.shape}"
        )
    weights = parse_space(space) if isinstance(space, str) else tuple(np.asarray(space, float))
    if isinstance(weights, str):  # "auto"
        weights, _ = search_space(image, axis=axis)
    return monochrome(image, weights), weights


def extract(
    image: ArrayLike,
    method: str,
    *,
    space: Any = None,
    stripe: str = "h",
    sigma: float | None = None,
    med_options: dict | None = None,
    **params,
) -> Centres:
    """Stripe centres of one frame by any method of Table 6.

    Args:
        image: (H, W, 3) RGB frame, or (H, W) monochrome.
        method: one of `METHODS`.
        space: colour space, see `monochrome_for`; default (None) R−G, the paper's choice, and
            "auto" (the clip-aware kurtosis search) for "linked".
        stripe: "h" — horizontal stripe, one centre per column (`pos` = row v, N = W);
            "v" — vertical stripe, one centre per row (`pos` = column u, N = H).
        sigma: Steger's Gaussian scale, px ("steger", "med": default `DEFAULT_SIGMA`;
            "linked": default None, chosen from the measured stripe width).
        med_options: keyword arguments of `cslx.segmentation.med.med` ("med" only), e.g. L, init.
        **params: the method's own keywords (`steger_centres` thresholds for "steger"/"med",
            `cslx.segmentation.baselines.cm` / `la` / ... keywords for the baselines).

    Returns:
        `Centres` (pos, valid, strength); NumPy arrays for the baselines, JAX arrays for
        "steger" and "med".
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    axis = _axis(stripe)
    if method == "linked":
        from .robust import linked_extract

        shape = np.shape(image)[:2]
        along, across = (shape[1], shape[0]) if axis == 0 else shape
        if along < LINKED_MIN_ALONG or across < LINKED_MIN_ACROSS:
            raise ValueError(
                f"image is {shape[1]}×{shape[0]} px: the linked detector needs at least "
                f"{LINKED_MIN_ALONG} px along the stripe and {LINKED_MIN_ACROSS} across"
            )

        return linked_extract(
            image, space="auto" if space is None else space, stripe=stripe, sigma=sigma, **params
        )
    space = "r-g" if space is None else space
    sigma = DEFAULT_SIGMA if sigma is None else sigma
    mono, _ = monochrome_for(image, space, stripe)
    if method in _BASELINES:
        return _BASELINES[method](np.asarray(mono), axis, **params)
    if method == "med":
        from .med import med

        result = med(mono, axis=axis, **(med_options or {}))
        mono = result.output  # delay-compensated, sign chosen so the stripe is bright
    return steger_centres(mono, sigma=sigma, axis=axis, **params)


def centres_to_pixels(centres: Centres, stripe: str) -> np.ndarray:
    """(N, 2) OpenCV pixel coordinates (u, v) of centres, NaN rows where not valid.

    For stripe "h" the n-th centre lies in column u = n at row `pos`; for "v" in row v = n at
    column `pos`.
    """
    axis = _axis(stripe)
    pos = np.asarray(centres.pos, float)
    valid = np.asarray(centres.valid, bool)
    pos = np.where(valid & np.isfinite(pos), pos, np.nan)
    index = np.arange(len(pos), dtype=float)
    index = np.where(np.isnan(pos), np.nan, index)
    uv = np.stack([index, pos] if axis == 0 else [pos, index], axis=-1)
    return uv
