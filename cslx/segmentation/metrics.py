"""The error metrics of every accuracy table (docs/metrics.md).

For each ground-truth column (horizontal stripe) or row (vertical stripe) the estimated centre
is triangulated with the true calibration and compared in 3-D with the true surface point:
mean, median, 95th percentile, pixel error, detection rate and gross outliers (> `GROSS_MM`)
side by side, so that a method that drops hard columns cannot look better for it.
"""

from __future__ import annotations

import math

import jax.numpy as jnp
import numpy as np
from numpy.typing import ArrayLike

__all__ = ["GROSS_MM", "stripe_errors", "stripe_point_errors"]


#: A centre whose 3-D error exceeds this is a gross outlier (mm).
GROSS_MM = 1.0


def stripe_errors(
    uv_est: ArrayLike,
    gt_xyz: ArrayLike,
    sensor,
    plane: int,
    *,
    gross_mm: float = GROSS_MM,
) -> dict[str, float]:
    """Score estimated centres of one stripe against ground truth (docs/metrics.md.

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
    from ..sensor import triangulate
    from ..sensor.camera import project

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
