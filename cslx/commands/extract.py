"""Extract laser stripe centres from images into a centre CSV.

Writes one row per centre with header `image,stripe,u,v` (plus `x,y,z` in mm, camera frame,
when --calib is given): stripe `h` has at most one centre per image column, stripe `v` at
most one per image row; pixel coordinates are OpenCV's (origin at the centre of the top-left
pixel). Unreadable images, images of another size than the calibration and frames without a
stripe are reported on stderr; the other images are still processed, and the exit status is
non-zero if any image failed.
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

NAME = "extract"
HELP = "stripe centres of images → centre CSV (CM, LA, QA, AA, Steger, MED + Steger)"

METHODS = ("cm", "la", "qa", "aa", "steger", "med")


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("images", nargs="+", metavar="IMAGE", help="image files (PNG, JPEG, …)")
    parser.add_argument(
        "--method", choices=METHODS, default="med", help="segmentation method (default: med)"
    )
    parser.add_argument(
        "--space",
        default="r-g",
        help="colour space: r, r-g, gray, auto (kurtosis search) or W_R,W_G,W_B (default r-g)",
    )
    parser.add_argument(
        "--stripe",
        choices=("h", "v", "both"),
        default="both",
        help="horizontal (h), vertical (v) or both stripes of the cross (default both)",
    )
    parser.add_argument(
        "--sigma", type=float, default=None, help="Steger's Gaussian scale in pixels (default 2)"
    )
    parser.add_argument("--calib", metavar="FILE", help="calibration JSON: adds x,y,z in mm")
    parser.add_argument("--out", metavar="FILE.csv", required=True, help="centre CSV to write")


def _read_rgb(path: str):
    import cv2

    if not os.path.isfile(path):
        raise OSError("no such file")
    bgr = cv2.imread(path, cv2.IMREAD_COLOR)
    if bgr is None:
        raise OSError("not a readable image")
    return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)


def run(args: argparse.Namespace) -> int:
    import numpy as np
    from tqdm import tqdm

    from ..colour import parse_space
    from ..segment import DEFAULT_SIGMA, centres_to_pixels, extract
    from ..sensor import CalibrationError, load_sensor, triangulate

    try:
        parse_space(args.space)
    except ValueError as err:
        print(f"cslx extract: {err}", file=sys.stderr)
        return 2
    sensor = None
    if args.calib:
        try:
            sensor = load_sensor(args.calib)
        except (OSError, CalibrationError) as err:
            print(f"cslx extract: calibration {args.calib}: {err}", file=sys.stderr)
            return 2
    stripes = ("h", "v") if args.stripe == "both" else (args.stripe,)
    sigma = args.sigma if args.sigma is not None else DEFAULT_SIGMA
    header = ["image", "stripe", "u", "v"] + (["x", "y", "z"] if sensor is not None else [])

    failed = 0
    try:
        out = open(args.out, "w", newline="")
    except OSError as err:
        print(f"cslx extract: cannot write {args.out}: {err}", file=sys.stderr)
        return 2
    with out:
        writer = csv.writer(out)
        writer.writerow(header)
        images = tqdm(args.images, unit="img", disable=len(args.images) < 10, file=sys.stderr)
        for path in images:
            try:
                rgb = _read_rgb(path)
            except OSError as err:
                print(f"cslx extract: {path}: {err}; skipped", file=sys.stderr)
                failed += 1
                continue
            h, w = rgb.shape[:2]
            if sensor is not None and tuple(sensor.camera.image_size) != (w, h):
                print(
                    f"cslx extract: {path}: image is {w}×{h} but the calibration is for "
                    f"{sensor.camera.image_size[0]}×{sensor.camera.image_size[1]}; skipped",
                    file=sys.stderr,
                )
                failed += 1
                continue
            found = 0
            for stripe in stripes:
                kw = {} if args.method in ("cm", "la", "qa", "aa") else {"sigma": sigma}
                try:
                    centres = extract(rgb, args.method, space=args.space, stripe=stripe, **kw)
                except Exception as err:  # one bad frame must not lose the others
                    print(f"cslx extract: {path}: stripe {stripe}: {err}", file=sys.stderr)
                    continue
                uv = centres_to_pixels(centres, stripe)
                ok = np.all(np.isfinite(uv), axis=1)
                uv = uv[ok]
                found += len(uv)
                if len(uv) == 0:
                    continue
                rows = [[path, stripe, f"{u:.4f}", f"{v:.4f}"] for u, v in uv]
                if sensor is not None:
                    xyz = np.asarray(triangulate(sensor, uv, 0 if stripe == "h" else 1))
                    for row, p in zip(rows, xyz, strict=True):
                        row.extend(f"{c:.4f}" for c in p)
                writer.writerows(rows)
            if found == 0:
                print(f"cslx extract: {path}: no stripe found", file=sys.stderr)
                failed += 1
    if failed:
        print(f"cslx extract: {failed} of {len(args.images)} images failed", file=sys.stderr)
    return 1 if failed else 0
