"""The calibration file: JSON read, validated and written (the project's file contract).

Keys: `image_size` [w, h], `K` 3×3, `dist` [k1, k2, p1, p2], `rms_px`, `planes`
[[a1,b1,c1], …] (1 or 2 planes, camera frame, mm, plane i: a x + b y + c z + 1 = 0; the
horizontal stripe's first), `R_cr` 3×3, `T_cr` [3] (mm), plus optional extras that are kept
verbatim. See docs/contracts.md.

One plane or two: a cross projector has two planes (horizontal stripe, then vertical); a
single line laser has one. The optional key `stripes` (["h"], ["v"] or ["h", "v"]) names the
stripe of each plane; without it the planes are ("h", "v")[:len(planes)], so a one-plane file
without `stripes` is a horizontal line. `cslx calibrate` always writes `stripes`.

Extras written by `cslx calibrate` (`cslx.calibration.calibrate_sensor`), per plane in the
order of `planes`: `plane_rms_mm` (RMS orthogonal distance of the inliers), `plane_points`
(inliers), `plane_outliers`, `plane_inlier_share`, `plane_std` (standard deviations of
a, b, c), `plane_covariance` (3×3 covariance of a, b, c, σ²(JᵀJ)⁻¹), `plane_views`; and
`plane_angle_deg` (two planes only), `lines_detected` (the stripes found in the images) and
`rejected_lines` (stripe → reason for each candidate line that was not kept).

A camera-only file (`cslx calibrate --camera-only`: `"camera_only": true`, no `planes`) is
refused by `load_sensor` with words that say so.
"""

from __future__ import annotations

import datetime as _dt
import json
import math
import os
from typing import Any

import numpy as np

from .rig import CalibrationError, Sensor, plane_angle_deg, sensor_from_arrays


def _array(data: dict, key: str, shape: tuple[int, ...], path: str) -> np.ndarray:
    if key not in data:
        raise CalibrationError(f"{path}: missing key {key!r}")
    try:
        arr = np.asarray(data[key], dtype=float)
    except (TypeError, ValueError) as e:
        raise CalibrationError(f"{path}: {key!r} is not numeric ({e})") from None
    if arr.shape != shape:
        raise CalibrationError(f"{path}: {key!r} must have shape {shape}, got {arr.shape}")
    if not np.all(np.isfinite(arr)):
        raise CalibrationError(f"{path}: {key!r} holds a non-finite number")
    return arr


def validate_calibration(data: Any, path: str = "<calibration>") -> dict[str, np.ndarray]:
    """Check a decoded calibration JSON object; return its arrays or raise `CalibrationError`."""
    if not isinstance(data, dict):
        raise CalibrationError(f"{path}: the top level must be a JSON object")
    size = _array(data, "image_size", (2,), path)
    if np.any(size <= 0) or np.any(size != np.round(size)):
        raise CalibrationError(f"{path}: 'image_size' must be two positive integers [w, h]")
    K = _array(data, "K", (3, 3), path)
    if K[0, 0] <= 0 or K[1, 1] <= 0:
        raise CalibrationError(f"{path}: 'K' focal lengths must be positive")
    if not np.allclose(K[2], [0, 0, 1]) or K[1, 0] != 0:
        raise CalibrationError(f"{path}: 'K' must be [[fx,0,u0],[0,fy,v0],[0,0,1]]")
    d = data.get("dist")
    d = d[0] if isinstance(d, list) and len(d) == 1 and isinstance(d[0], list) else d
    if isinstance(d, list) and len(d) == 5:  # OpenCV's default output, (1, 5) or (5,)
        raise CalibrationError(
            f"{path}: 'dist' must be [k1, k2, p1, p2], got 5 numbers (OpenCV's k1, k2, p1, p2, "
            "k3?): cslx's lens model has no k3 (docs/contracts.md); calibrate with k3 fixed at "
            "0 (cv2.CALIB_FIX_K3) or with `cslx calibrate`"
        )
    dist = _array(data, "dist", (4,), path)
    if "planes" not in data:
        if data.get("camera_only"):
            raise CalibrationError(
                f"{path}: a camera-only calibration (intrinsics without laser planes, written "
                "by `cslx calibrate --camera-only`): triangulation needs the laser planes; "
                "calibrate again with --laser-images"
            )
        raise CalibrationError(
            f"{path}: missing key 'planes' (the laser planes): this file has no laser "
            "calibration; run `cslx calibrate` with --laser-images"
        )
    planes = np.asarray(data["planes"], dtype=object)
    n_planes = len(planes) if planes.ndim >= 1 else 0
    if n_planes not in (1, 2):
        raise CalibrationError(
            f"{path}: 'planes' must hold one plane (a line laser) or two (a cross), got {n_planes}"
        )
    planes = _array(data, "planes", (n_planes, 3), path)
    stripes = data.get("stripes", ["h", "v"][:n_planes])
    if (
        not isinstance(stripes, list)
        or len(stripes) != n_planes
        or not all(s in ("h", "v") for s in stripes)
        or len(set(stripes)) != n_planes
    ):
        raise CalibrationError(
            f'{path}: \'stripes\' must name the stripe of each plane once, "h" or "v" '
            f"({n_planes} plane(s)), got {stripes!r}"
        )
    norms = np.linalg.norm(planes, axis=1)
    if np.any(norms < 1e-12):
        raise CalibrationError(
            f"{path}: 'planes' has a zero normal (a plane through the camera centre or at "
            "infinity cannot be written a x + b y + c z + 1 = 0)"
        )
    if np.any(1.0 / norms < 1.0):
        raise CalibrationError(
            f"{path}: a laser plane passes within 1 mm of the camera centre "
            f"(distances {np.round(1.0 / norms, 3).tolist()} mm): it cannot triangulate"
        )
    R = _array(data, "R_cr", (3, 3), path)
    if not np.allclose(R.T @ R, np.eye(3), atol=1e-6) or np.linalg.det(R) < 0:
        raise CalibrationError(
            f"{path}: 'R_cr' is not a proper rotation (RᵀR − I max "
            f"{np.abs(R.T @ R - np.eye(3)).max():.2e}, det {np.linalg.det(R):.4f})"
        )
    T = _array(data, "T_cr", (3,), path)
    rms = data.get("rms_px", float("nan"))
    if rms is not None and not isinstance(rms, int | float):
        raise CalibrationError(f"{path}: 'rms_px' must be a number")
    return dict(
        image_size=size.astype(int), K=K, dist=dist, planes=planes, R_cr=R, T_cr=T,
        stripes=tuple(stripes),
    )  # fmt: skip


def load_sensor(path: str | os.PathLike, dtype=None) -> Sensor:
    """Read a calibration JSON file (docs/contracts.md) into a `Sensor` (one or two planes).

    Raises:
        CalibrationError: unreadable file, a directory, invalid JSON, a camera-only
            calibration, a missing key, a wrong shape, a non-finite number, a plane through
            the camera centre, or an `R_cr` that is not a rotation; the message names the
            file and the problem.
    """
    path = os.fspath(path)
    if os.path.isdir(path):
        raise CalibrationError(f"{path}: is a directory, not a calibration JSON file")
    try:
        with open(path, encoding="utf-8") as f:
            data = json.load(f)
    except FileNotFoundError:
        raise CalibrationError(f"{path}: no such calibration file") from None
    except (OSError, UnicodeDecodeError) as e:
        raise CalibrationError(f"{path}: cannot read ({e})") from None
    except json.JSONDecodeError as e:
        raise CalibrationError(f"{path}: not valid JSON ({e})") from None
    a = validate_calibration(data, path)
    return sensor_from_arrays(
        a["K"], a["dist"], a["planes"], a["R_cr"], a["T_cr"], tuple(a["image_size"]), dtype,
        stripes=a["stripes"],
    )  # fmt: skip


def sensor_to_dict(
    sensor: Sensor, rms_px: float = float("nan"), *, stamp: bool = False, **extra: Any
) -> dict:
    """The calibration JSON object of a sensor, plus any extra fields.

    `stamp` adds the current UTC date (left out by default so that rendered data sets are
    byte-for-byte reproducible).
    """
    cam = sensor.camera
    out = {
        "image_size": [int(cam.image_size[0]), int(cam.image_size[1])],
        "K": np.asarray(cam.K, float).tolist(),
        "dist": np.asarray(cam.dist, float).tolist(),
        "rms_px": None if not math.isfinite(rms_px) else float(rms_px),
        "planes": np.asarray(sensor.planes, float).tolist(),
        "R_cr": np.asarray(sensor.R_cr, float).tolist(),
        "T_cr": np.asarray(sensor.T_cr, float).tolist(),
        "stripes": list(sensor.plane_stripes),
    }
    if sensor.n_planes == 2:
        out["plane_angle_deg"] = plane_angle_deg(sensor.planes[0], sensor.planes[1])
    if stamp:
        out["date"] = _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds")
    out.update(extra)
    return out


def save_sensor(
    sensor: Sensor,
    path: str | os.PathLike,
    rms_px: float = float("nan"),
    *,
    stamp: bool = False,
    **extra: Any,
) -> None:
    """Write a `Sensor` as the calibration JSON of docs/contracts.md (extras added verbatim).

    Written atomically (`cslx.files.atomic_write`): a failure leaves the previous file intact.
    """
    write_json_atomic(path, sensor_to_dict(sensor, rms_px, stamp=stamp, **extra))


def write_json_atomic(path: str | os.PathLike, data: dict) -> None:
    """`json.dump` through `cslx.files.atomic_write`: the file appears whole or not at all."""
    from ..files import atomic_write

    with atomic_write(path, "w", encoding="utf-8") as f:
        json.dump(data, f, indent=1)
        f.write("\n")
