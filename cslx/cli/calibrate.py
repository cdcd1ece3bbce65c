"""Calibrate the camera, both laser planes and the camera-to-robot transform.

Plain chessboard images (--images) give the camera by Zhang's method with a joint
Levenberg–Marquardt refinement; laser-on images of the same poses (--laser-images, paired
with the plain images in sorted file-name order) give both laser planes; a CSV of target
points known in both frames (--robot-points, header x_c,y_c,z_c,x_r,y_r,z_r, mm) gives R_cr
and T_cr by a rigid fit (without it, R_cr = I and T_cr = 0 and the file says so).

The calibration file must hold both planes (docs/contracts.md), so --laser-images is required; with
--camera-only the command writes the intrinsics alone, with "camera_only": true and no
planes, which `cslx.sensor.load_sensor` will refuse. Images without a detectable board are
listed and skipped. A summary table goes to stdout.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys

NAME = "calibrate"
HELP = "chessboard (+ laser) images → calibration JSON (camera, laser planes, robot frame)"

_EXTS = (".png", ".jpg", ".jpeg", ".bmp", ".tif", ".tiff")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("--images", required=True, metavar="DIR_OR_GLOB", help="plain images")
    parser.add_argument(
        "--pattern", default="10x7", help="inner corners COLSxROWS (default 10x7, the paper's)"
    )
    parser.add_argument("--square", type=float, default=25.0, help="square side in mm (default 25)")
    parser.add_argument(
        "--laser-images", metavar="DIR_OR_GLOB", help="laser-on images of the same poses"
    )
    parser.add_argument(
        "--robot-points", metavar="FILE.csv", help="x_c,y_c,z_c,x_r,y_r,z_r rows (mm)"
    )
    parser.add_argument(
        "--method",
        default="auto",
        help="stripe centres: simple, steger, med, … or auto (steger when available)",
    )
    parser.add_argument(
        "--camera-only",
        action="store_true",
        help="without laser images: write the intrinsics only (not loadable as a sensor)",
    )
    parser.add_argument("--out", required=True, metavar="FILE.json", help="calibration JSON")


def _list_images(spec: str) -> list[str]:
    if os.path.isdir(spec):
        files = [os.path.join(spec, f) for f in os.listdir(spec)]
        files = [f for f in files if f.lower().endswith(_EXTS)]
    else:
        files = glob.glob(spec)
    return sorted(files)


def _parse_pattern(text: str) -> tuple[int, int]:
    try:
        cols, rows = (int(x) for x in text.lower().split("x"))
    except ValueError:
        raise ValueError(f"--pattern must look like 10x7, got {text!r}") from None
    if cols < 2 or rows < 2:
        raise ValueError(f"--pattern needs at least 2x2 inner corners, got {text!r}")
    return cols, rows


def _read_robot_points(path: str):
    import numpy as np

    try:
        data = np.genfromtxt(path, delimiter=",", names=True)
    except OSError as e:
        raise ValueError(f"{path}: cannot read ({e})") from None
    need = ("x_c", "y_c", "z_c", "x_r", "y_r", "z_r")
    names = data.dtype.names or ()
    missing = [n for n in need if n not in names]
    if missing:
        raise ValueError(f"{path}: missing columns {missing} (header {list(names)})")
    data = np.atleast_1d(data)
    Pc = np.stack([data[n] for n in need[:3]], 1)
    Pr = np.stack([data[n] for n in need[3:]], 1)
    return Pc, Pr


def _fail(msg: str) -> int:
    print(f"cslx calibrate: {msg}", file=sys.stderr)
    return 2


def run(args: argparse.Namespace) -> int:
    import json
    import time

    import cv2
    import numpy as np

    from ..calibration import (
        board_points,
        calibrate_camera,
        calibrate_planes,
        detect_corners,
        fit_rigid,
    )
    from ..sensor import CalibrationError, Sensor, save_sensor

    try:
        pattern = _parse_pattern(args.pattern)
    except ValueError as e:
        return _fail(str(e))
    if not args.laser_images and not args.camera_only:
        return _fail(
            "--laser-images is required: the calibration file must hold both laser planes "
            "(docs/contracts.md); pass --camera-only to write the intrinsics alone"
        )
    images = _list_images(args.images)
    if not images:
        return _fail(f"no images match {args.images!r}")
    lasers = _list_images(args.laser_images) if args.laser_images else []
    if args.laser_images and len(lasers) != len(images):
        return _fail(
            f"{len(lasers)} laser images for {len(images)} plain images: they are paired in "
            "sorted name order and must be equally many"
        )
    t0 = time.perf_counter()
    try:
        corners, skipped = detect_corners(images, pattern)
    except (FileNotFoundError, ValueError) as e:
        return _fail(str(e))
    keep = [i for i, c in enumerate(corners) if c is not None]
    for name in skipped:
        print(f"cslx calibrate: no {args.pattern} board found in {name}; skipped", file=sys.stderr)
    if len(keep) < 3:
        return _fail(f"the board was found in {len(keep)} images; at least 3 are needed")
    first = cv2.imread(images[keep[0]], cv2.IMREAD_GRAYSCALE)
    size = (first.shape[1], first.shape[0])
    obj = board_points(pattern, args.square)
    try:
        cal = calibrate_camera([corners[i] for i in keep], obj, size)
    except CalibrationError as e:
        return _fail(str(e))
    names = [os.path.basename(images[i]) for i in keep]
    cam = cal.camera
    extras = dict(
        pattern=list(pattern),
        square_mm=args.square,
        images=names,
        skipped_images=[os.path.basename(s) for s in skipped],
        per_image_rms_px=dict(zip(names, map(float, cal.per_image_rms), strict=True)),
        std={k: float(v) for k, v in cal.std.items() if k not in ("rvecs", "tvecs")},
        lm_steps=cal.n_iter,
        lm_converged=cal.converged,
        corner_method="cv2.findChessboardCorners + cornerSubPix(win=(5,5), EPS+COUNT 30 0.1)",
    )
    planes = None
    if lasers:
        try:
            pc = calibrate_planes(cal, [lasers[i] for i in keep], pattern, args.square,
                                  method=args.method)  # fmt: skip
        except (CalibrationError, FileNotFoundError) as e:
            return _fail(f"laser planes: {e}")
        planes = pc.planes
        extras.update(
            plane_rms_mm=[f.rms for f in pc.fits],
            plane_points=[int(f.inliers.sum()) for f in pc.fits],
            plane_outliers=[int((~f.inliers).sum()) for f in pc.fits],
            plane_std=[f.std.tolist() for f in pc.fits],
            plane_covariance=[f.covariance.tolist() for f in pc.fits],
            stripe_points_per_image={n: c.tolist() for n, c in zip(names, pc.counts, strict=True)},
            stripe_method=args.method,
        )
    R_cr, T_cr = np.eye(3), np.zeros(3)
    extras["robot_frame"] = "identity (no --robot-points)"
    if args.robot_points:
        try:
            Pc, Pr = _read_robot_points(args.robot_points)
            R_cr, T_cr, res = fit_rigid(Pc, Pr)
        except (ValueError, CalibrationError) as e:
            return _fail(f"robot points: {e}")
        extras["robot_frame"] = f"rigid fit of {len(Pc)} points in {args.robot_points}"
        extras["robot_residuals_mm"] = res.tolist()
    elapsed = time.perf_counter() - t0
    extras["calibration_time_s"] = elapsed

    if planes is None:
        data = dict(
            image_size=list(size),
            K=np.asarray(cam.K).tolist(),
            dist=np.asarray(cam.dist).tolist(),
            rms_px=cal.rms,
            camera_only=True,
            **extras,
        )
        with open(args.out, "w", encoding="utf-8") as f:
            json.dump(data, f, indent=1)
            f.write("\n")
    else:
        import jax.numpy as jnp

        sensor = Sensor(cam, jnp.asarray(planes), jnp.asarray(R_cr), jnp.asarray(T_cr))
        save_sensor(sensor, args.out, cal.rms, stamp=True, **extras)

    # Summary table.
    print(f"camera  ({len(keep)} of {len(images)} images, {cal.n_iter} LM steps, {elapsed:.1f} s)")
    for k, v in (("fx", cam.fx), ("fy", cam.fy), ("u0", cam.u0), ("v0", cam.v0)):
        print(f"  {k:3s} {float(v):12.4f} ± {cal.std[k]:.4f} px")
    for k, v in zip(("k1", "k2", "p1", "p2"), np.asarray(cam.dist), strict=True):
        print(f"  {k:3s} {float(v):12.6f} ± {cal.std[k]:.6f}")
    print(f"  RMS reprojection error {cal.rms:.4f} px")
    print("  image                          RMS px")
    for n, e in zip(names, cal.per_image_rms, strict=True):
        print(f"  {n:30s} {e:.4f}")
    if planes is not None:
        for k, f in enumerate(pc.fits):
            a, b, c = f.plane
            print(
                f"plane {k} ({'hv'[k]}): {a:+.6e} x {b:+.6e} y {c:+.6e} z + 1 = 0   "
                f"RMS {f.rms:.4f} mm, {int(f.inliers.sum())} points, "
                f"{int((~f.inliers).sum())} outliers"
            )
        print(f"angle between the planes {pc.angle_deg:.4f}°")
    if args.robot_points:
        print(f"robot frame: RMS residual {float(np.sqrt(np.mean(res**2))):.4f} mm")
    print(f"wrote {args.out}")
    return 0
