"""One interface to every stripe segmentation method of Table 6, and the metrics of DESIGN.md.

`extract(image, method, space=..., stripe=...)` turns an RGB frame into per-column (horizontal
stripe) or per-row (vertical stripe) centres with any of `METHODS`:

- ``"cm"``, ``"la"``, ``"qa"``, ``"aa"``: the baselines of `cslx.baselines`;
- ``"steger"``: Steger's detector (`cslx.steger`) on the monochrome image, no MED;
- ``"med"``: the paper's full method (sections 3.1–3.3): MED along the stripe's search
  direction (`cslx.med.med`, delay-compensated output aligned with the image), then Steger.

`centres_to_pixels` turns centres into OpenCV pixel coordinates and `stripe_errors` scores
them against rendered ground truth exactly as DESIGN.md ("Metrics") defines.
"""

from __future__ import annotations

import math
from typing import Any

import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

from . import baselines
from .steger import Centres, steger_centres

__all__ = [
    "METHODS",
    "STRIPES",
    "DEFAULT_SIGMA",
    "GROSS_MM",
    "centres_to_pixels",
    "extract",
    "monochrome_for",
    "stripe_errors",
]

METHODS = ("cm", "la", "qa", "aa", "steger", "med")
STRIPES = ("h", "v")
#: Steger scale for the rendered stripes (Gaussian sheet profile of ≈ 2 px std at 230 mm).
DEFAULT_SIGMA = 2.0
#: A 3-D error above this many mm is a gross outlier (DESIGN.md, Metrics).
GROSS_MM = 1.0

_BASELINES = {"cm": baselines.cm, "la": baselines.la, "qa": baselines.qa, "aa": baselines.aa}


def _axis(stripe: str) -> int:
    if stripe not in STRIPES:
        raise ValueError(f"stripe must be 'h' (horizontal) or 'v' (vertical), got {stripe!r}")
    return 0 if stripe == "h" else 1


def monochrome_for(image: ArrayLike, space: Any = "r-g", stripe: str = "h"):
    """The monochrome image of a frame in a colour space (section 3.1, eq. (8)).

    Args:
        image: (H, W, 3) RGB frame (uint8 or float), or an (H, W) frame already monochrome
            (returned unchanged as float; `space` is then ignored).
        space: a name or weights string for `cslx.colour.parse_space` ("r", "r-g", "gray",
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
    space: Any = "r-g",
    stripe: str = "h",
    sigma: float = DEFAULT_SIGMA,
    med_options: dict | None = None,
    **params,
) -> Centres:
    """Stripe centres of one frame by any method of Table 6.

    Args:
        image: (H, W, 3) RGB frame, or (H, W) monochrome.
        method: one of `METHODS`.
        space: colour space, see `monochrome_for` (default R−G, the paper's choice).
        stripe: "h" — horizontal stripe, one centre per column (`pos` = row v, N = W);
            "v" — vertical stripe, one centre per row (`pos` = column u, N = H).
        sigma: Steger's Gaussian scale, px ("steger" and "med" only).
        med_options: keyword arguments of `cslx.med.med` ("med" only), e.g. L, init.
        **params: the method's own keywords (`steger_centres` thresholds for "steger"/"med",
            `cslx.baselines.cm` / `la` / ... keywords for the baselines).

    Returns:
        `Centres` (pos, valid, strength); NumPy arrays for the baselines, JAX arrays for
        "steger" and "med".
    """
    if method not in METHODS:
        raise ValueError(f"unknown method {method!r}: use one of {', '.join(METHODS)}")
    axis = _axis(stripe)
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


def stripe_errors(
    uv_est: ArrayLike,
    gt_xyz: ArrayLike,
    sensor,
    plane: int,
    *,
    gross_mm: float = GROSS_MM,
) -> dict[str, float]:
    """Score estimated centres of one stripe against ground truth (DESIGN.md, Metrics).

    The estimate of each column (row) is triangulated with the true calibration
    (`cslx.sensor.triangulate`) and compared with the ground-truth 3-D point of the same
    column (row). A ground-truth column without an estimate lowers the detection rate; an
    estimate where the ground truth is NaN (no stripe there) is a false positive.

    Args:
        uv_est: (N, 2) estimated pixel coordinates, NaN rows where nothing was found
            (`centres_to_pixels`).
        gt_xyz: (N, 3) ground-truth points, camera frame, mm; NaN where the stripe is absent.
        sensor: the true `cslx.sensor.Sensor`.
        plane: 0 for the horizontal stripe, 1 for the vertical one.
        gross_mm: 3-D error above which a matched centre is a gross outlier.

    Returns:
        dict: mean_mm, median_mm, p95_mm, max_mm (matched centres; NaN if none), mean_px
        (image distance to the projected ground truth), detection_rate (matched / ground
        truth), gross_outliers (count of matched errors > gross_mm), false_positives (count),
        n_gt, n_matched.
    """

    uv_est = np.asarray(uv_est, float)
    gt_xyz = np.asarray(gt_xyz, float)
    if uv_est.ndim != 2 or uv_est.shape[1] != 2:
        raise ValueError(f"uv_est must have shape (N, 2), got {uv_est.shape}")
    if gt_xyz.shape != (uv_est.shape[0], 3):
        raise ValueError(
            f"gt_xyz must have shape ({uv_est.shape[0]}, 3) to match uv_est, got {gt_xyz.shape}"
        )
    err, err_px, n_gt, n_fp = stripe_point_errors(uv_est, gt_xyz, sensor, plane)
    n_matched = len(err)
    nan = math.nan
    out = dict(
        mean_mm=nan,
        median_mm=nan,
        p95_mm=nan,
        max_mm=nan,
        mean_px=nan,
        detection_rate=(n_matched / n_gt) if n_gt else nan,
        gross_outliers=0,
        false_positives=n_fp,
        n_gt=n_gt,
        n_matched=n_matched,
    )
    if n_matched == 0:
        return out
    out.update(
        mean_mm=float(np.mean(err)),
        median_mm=float(np.median(err)),
        p95_mm=float(np.percentile(err, 95)),
        max_mm=float(np.max(err)),
        mean_px=float(np.mean(err_px)),
        gross_outliers=int(np.sum(err > gross_mm)),
    )
    return out


def stripe_point_errors(
    uv_est: ArrayLike, gt_xyz: ArrayLike, sensor, plane: int
) -> tuple[np.ndarray, np.ndarray, int, int]:
    """Per-centre errors behind `stripe_errors`: (err_mm, err_px, n_gt, false_positives).

    `err_mm` and `err_px` hold one entry per matched column (row): the 3-D distance of the
    triangulated estimate (true calibration) to the ground-truth point, and the image distance
    to the projected ground truth. Triangulation and projection run on full-length arrays
    (placeholders where unmatched), so their compiled programs have one shape per stripe and
    are not recompiled for every match count.
    """
    from .camera import project
    from .sensor import triangulate

    uv_est = np.asarray(uv_est, float)
    gt_xyz = np.asarray(gt_xyz, float)
    est_ok = np.all(np.isfinite(uv_est), axis=1)
    gt_ok = np.all(np.isfinite(gt_xyz), axis=1)
    m = est_ok & gt_ok
    n_gt, n_fp = int(gt_ok.sum()), int((est_ok & ~gt_ok).sum())
    if not m.any():
        return np.zeros(0), np.zeros(0), n_gt, n_fp
    dtype = sensor.planes.dtype
    centre = np.array([sensor.camera.u0, sensor.camera.v0], float)
    uv_full = np.where(m[:, None], uv_est, centre)
    gt_full = np.where(m[:, None], gt_xyz, np.array([0.0, 0.0, 1.0]))
    xyz = np.asarray(triangulate(sensor, jnp.asarray(uv_full, dtype), plane))[m]
    err = np.linalg.norm(xyz - gt_xyz[m], axis=1)
    err = np.where(np.isfinite(err), err, np.inf)  # a ray parallel to the plane is a miss
    gt_uv = np.asarray(project(jnp.asarray(gt_full, dtype), sensor.camera))[m]
    return err, np.linalg.norm(uv_est[m] - gt_uv, axis=1), n_gt, n_fp
