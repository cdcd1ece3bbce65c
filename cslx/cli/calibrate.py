"""Calibrate the camera, the laser plane(s) and the camera-to-robot transform.

Plain chessboard images (--images) give the camera by Zhang's method with a joint
Levenberg–Marquardt refinement; laser-on images of the same poses (--laser-images, paired
with the plain images in sorted file-name order) give the laser planes. --laser-images may
name the same images as --images: one photo per pose with the laser on is enough, the
corners are found around the line and the line's centres are taken inside the board only.

The number of laser lines — one line laser, or a cross — is found from the images (--lines
1 or 2 forces it); the calibration file then holds one plane or two (horizontal first, with
"stripes" naming each; docs/contracts.md). A plane whose fit is poor (RMS, inlier share, too
few points or poses) is refused with the reason, never written.

A CSV of target points known in both frames (--robot-points, header x_c,y_c,z_c,x_r,y_r,z_r,
mm) gives R_cr and T_cr by a rigid fit (without it, R_cr = I and T_cr = 0 and the file says
so). With --camera-only the command writes the intrinsics alone, with "camera_only": true and
no planes, which `cslx.sensor.load_sensor` refuses with words that say so.

Unreadable images, images of another size and images without a detectable board are
skipped with a warning each and counted; at least three usable poses are needed. The file
is written atomically. A summary table goes to stdout.
"""

from __future__ import annotations

import argparse
import glob
import os
import sys

NAME = "calibrate"
HELP = "chessboard (+ laser) images → calibration JSON (camera, laser plane(s), robot frame)"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--images",
        required=True,
        metavar="DIR_OR_GLOB",
        help="chessboard images, one per pose (unreadable or boardless ones are skipped "
        "with a warning and counted)",
    )
    parser.add_argument(
        "--pattern", default="10x7", help="inner corners COLSxROWS (default 10x7, the paper's)"
    )
    parser.add_argument("--square", type=float, default=25.0, help="square side in mm (default 25)")
    parser.add_argument(
        "--laser-images",
        metavar="DIR_OR_GLOB",
        help="laser-on images of the same poses, paired by sorted name; may be the same "
        "images as --images (the line's centres are taken inside the board)",
    )
    parser.add_argument(
        "--lines",
        choices=("1", "2"),
        help="number of laser lines: 1 (a line laser) or 2 (a cross); default: found from "
        "the laser images",
    )
    parser.add_argument(
        "--robot-points", metavar="FILE.csv", help="x_c,y_c,z_c,x_r,y_r,z_r rows (mm)"
    )
    parser.add_argument(
        "--method",
        default="auto",
        help="stripe centres: simple, steger, med, … or auto (steger)",
    )
    parser.add_argument(
        "--camera-only",
        action="store_true",
        help="without laser images: write the intrinsics only (not loadable as a sensor)",
    )
    parser.add_argument("--out", required=True, metavar="FILE.json", help="calibration JSON")


def _list_images(spec: str) -> list[str]:
    if os.path.isdir(spec):
        from ..images import list_images

        return list_images(spec)
    return sorted(f for f in glob.glob(spec) if not os.path.isdir(f))


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

    if os.path.isdir(path):
        raise ValueError(f"{path}: is a directory, not a CSV file")
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


def _check_out(path: str) -> str | None:
    if os.path.isdir(path):
        return f"--out {path}: is a directory; name a .json file"
    folder = os.path.dirname(os.path.abspath(path))
    if not os.path.isdir(folder):
        return f"--out {path}: the folder {folder} does not exist"
    if not os.access(folder, os.W_OK):
        return f"--out {path}: the folder {folder} is not writable"
    return None


def run(args: argparse.Namespace) -> int:
    try:
        pattern = _parse_pattern(args.pattern)
    except ValueError as e:
        return _fail(str(e))
    if not args.square > 0 or args.square == float("inf"):
        return _fail(f"--square must be a positive number of mm, got {args.square}")
    if args.laser_images and args.camera_only:
        return _fail("--camera-only and --laser-images exclude each other")
    if not args.laser_images and not args.camera_only:
        return _fail(
            "--laser-images is required: the calibration file must hold the laser plane(s) "
            "(they may be the same images as --images); pass --camera-only to write the "
            "intrinsics alone"
        )
    problem = _check_out(args.out)
    if problem:
        return _fail(problem)
    images = _list_images(args.images)
    if not images:
        return _fail(f"no images match --images {args.images!r} (a folder or a glob)")
    lasers = _list_images(args.laser_images) if args.laser_images else None
    if lasers is not None and len(lasers) != len(images):
        return _fail(
            f"{len(lasers)} laser images for {len(images)} plain images: they are paired in "
            "sorted name order and must be equally many"
        )
    robot = None
    if args.robot_points:
        try:
            robot = _read_robot_points(args.robot_points)
        except ValueError as e:
            return _fail(f"robot points: {e}")
    return _calibrate(args, pattern, images, lasers, robot)


def _calibrate(args, pattern, images, lasers, robot) -> int:
    import numpy as np

    from ..calibration import calibrate_sensor

    def warn(msg: str) -> None:
        if msg.endswith("skipped"):
            print(f"cslx calibrate: warning: {msg}", file=sys.stderr)
        else:
            print(f"cslx calibrate: {msg}", file=sys.stderr, flush=True)

    try:
        result = calibrate_sensor(
            images, pattern, args.square, laser_images=lasers,
            lines=int(args.lines) if args.lines else None,
            method=args.method, robot_points=robot, log=warn,
        )  # fmt: skip
    except ValueError as e:  # CalibrationError included: bad views, no line, a poor plane
        return _fail(str(e))
    if result.skipped:
        print(
            f"cslx calibrate: warning: {len(result.skipped)} of {len(images)} images skipped "
            f"({len(result.used)} used)",
            file=sys.stderr,
        )
    try:
        result.save(args.out, stamp=True, stripe_method=args.method)
    except OSError as e:
        return _fail(f"cannot write {args.out}: {e}")

    # Summary table.
    cal, cam = result.camera, result.camera.camera
    print(
        f"camera  ({len(result.used)} of {len(images)} images, {cal.n_iter} LM steps, "
        f"{result.time_s:.1f} s)"
    )
    for k, v in (("fx", cam.fx), ("fy", cam.fy), ("u0", cam.u0), ("v0", cam.v0)):
        print(f"  {k:3s} {float(v):12.4f} ± {cal.std[k]:.4f} px")
    for k, v in zip(("k1", "k2", "p1", "p2"), np.asarray(cam.dist), strict=True):
        print(f"  {k:3s} {float(v):12.6f} ± {cal.std[k]:.6f}")
    print(f"  RMS reprojection error {cal.rms:.4f} px")
    print("  image                          RMS px")
    for i, e in zip(result.used, cal.per_image_rms, strict=True):
        print(f"  {os.path.basename(result.names[i]):30s} {e:.4f}")
    pc = result.planes
    if pc is not None:
        for k, (s, f) in enumerate(zip(pc.stripes, pc.fits, strict=True)):
            a, b, c = f.plane
            label = "horizontal" if s == "h" else "vertical"
            print(
                f"plane {k} ({label} line): {a:+.6e} x {b:+.6e} y {c:+.6e} z + 1 = 0   "
                f"RMS {f.rms:.4f} mm, {int(f.inliers.sum())} points, "
                f"{int((~f.inliers).sum())} outliers, std (a, b, c) "
                + ", ".join(f"{x:.2e}" for x in f.std)
            )
        if len(pc.stripes) == 2:
            print(f"angle between the planes {pc.angle_deg:.4f}°")
        else:
            print("one laser line: the file holds one plane")
        for why in pc.rejected.values():
            print(f"not a plane: {why}")
    if result.robot_residuals_mm is not None:
        res = result.robot_residuals_mm
        print(f"robot frame: RMS residual {float(np.sqrt(np.mean(res**2))):.4f} mm")
    print(f"wrote {args.out}")
    return 0
