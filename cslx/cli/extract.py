"""Extract laser stripe centres from images into a centre CSV.

Writes one row per centre with header `image,stripe,u,v` (plus `x,y,z` in mm, camera frame,
when --calib is given): stripe `h` has at most one centre per image column, stripe `v` at
most one per image row; pixel coordinates are OpenCV's (origin at the centre of the top-left
pixel). The default method "linked" adds the optional columns `sigma_px` (predicted standard
deviation of the centre along the search axis, px) and `saturated` (1: centre of a clipped
core, taken from the plateau's flanks). Unreadable images, images of another size than the
calibration and frames without a stripe are reported on stderr; the other images are still
processed, and the exit status is non-zero if any image failed.

With more than one JAX device (GPUs, several hosts, or CPU devices forced with
XLA_FLAGS=--xla_force_host_platform_device_count=N), the JAX methods (steger, med) with fixed
colour weights process the images in batches sharded over all devices (`cslx.segmentation.shard`).
"""

from __future__ import annotations

import argparse
import csv
import os
import sys

NAME = "extract"
HELP = "stripe centres of images → centre CSV (CM, LA, QA, AA, Steger, MED + Steger)"

METHODS = ("cm", "la", "qa", "aa", "steger", "med", "linked")
#: Default method: the linked detector (issue 11, evidence in results/robust_extraction.md);
#: the paper's MED + Steger stays available as --method med (Table 6).
DEFAULT_METHOD = "linked"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument("images", nargs="+", metavar="IMAGE", help="image files (PNG, JPEG, …)")
    parser.add_argument(
        "--method",
        choices=METHODS,
        default=DEFAULT_METHOD,
        help=f"segmentation method (default: {DEFAULT_METHOD}; the paper's: med)",
    )
    parser.add_argument(
        "--space",
        default=None,
        help="colour space: r, r-g, gray, auto (kurtosis search) or W_R,W_G,W_B "
        "(default: auto for linked, r-g for the others)",
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

    from ..segmentation import DEFAULT_SIGMA, centres_to_pixels, extract
    from ..segmentation.colour import parse_space
    from ..sensor import CalibrationError, load_sensor, triangulate

    if args.space is None:
        args.space = "auto" if args.method == "linked" else "r-g"
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
    extras = args.method == "linked"  # optional columns: predicted std (px), clipped core
    if extras:
        header += ["sigma_px", "saturated"]

    batched = _sharded_path(args)
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
            if batched is not None:
                batched.append((path, rgb))
                if len(batched) >= _BATCH_PER_DEVICE * batched.n_devices:
                    failed += _flush(batched, stripes, args, sigma, sensor, writer)
                continue
            found = 0
            for stripe in stripes:
                kw = {} if args.method in ("cm", "la", "qa", "aa") else {"sigma": sigma}
                if extras:
                    kw = {"sigma": args.sigma}
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
                if extras:
                    sig = np.asarray(centres.sigma)[ok]
                    sat = np.asarray(centres.saturated)[ok]
                    for row, s_px, s_f in zip(rows, sig, sat, strict=True):
                        row.extend([f"{s_px:.4f}", str(int(s_f))])
                writer.writerows(rows)
            if found == 0:
                print(f"cslx extract: {path}: no stripe found", file=sys.stderr)
                failed += 1
        if batched:
            failed += _flush(batched, stripes, args, sigma, sensor, writer)
    if failed:
        print(f"cslx extract: {failed} of {len(args.images)} images failed", file=sys.stderr)
    return 1 if failed else 0


# ---------------------------------------------------------------- several devices (cslx.segmentation.shard)
_BATCH_PER_DEVICE = 16


class _Pending(list):
    """Images read but not yet processed by the sharded path: [(path, rgb)], in input order."""

    n_devices = 1


def _sharded_path(args: argparse.Namespace) -> _Pending | None:
    """A pending list when the frames should be sharded over several devices, else None.

    Used for the JAX methods (steger, med) with fixed colour weights when JAX sees more than
    one device (GPUs, several hosts after `jax.distributed`, or forced CPU devices).
    """
    from ..segmentation.colour import parse_space
    from ..segmentation.shard import JAX_METHODS, initialize_distributed

    if args.method not in JAX_METHODS or parse_space(args.space) == "auto":
        return None
    import jax

    initialize_distributed()
    if jax.device_count() < 2:
        return None
    pending = _Pending()
    pending.n_devices = jax.device_count()
    from ..segmentation.shard import device_summary

    print(f"cslx extract: frames sharded over {device_summary()}", file=sys.stderr)
    return pending


def _flush(pending: _Pending, stripes, args, sigma, sensor, writer) -> int:
    """Centres of the pending images with `cslx.segmentation.shard.extract_batch`; rows in input order."""
    import numpy as np

    from ..segmentation import centres_to_pixels
    from ..segmentation.shard import extract_batch
    from ..segmentation.steger import Centres
    from ..sensor import triangulate

    rows: dict[int, list] = {i: [] for i in range(len(pending))}
    by_shape: dict[tuple, list[int]] = {}
    for i, (_, rgb) in enumerate(pending):
        by_shape.setdefault(rgb.shape, []).append(i)
    for idx in by_shape.values():
        frames = np.stack([pending[i][1] for i in idx])
        for stripe in stripes:
            try:
                c = extract_batch(frames, args.method, space=args.space, stripe=stripe, sigma=sigma)
            except Exception as err:  # one bad batch must not lose the others
                print(
                    f"cslx extract: batch of {len(idx)} images: stripe {stripe}: {err}",
                    file=sys.stderr,
                )
                continue
            for k, i in enumerate(idx):
                uv = centres_to_pixels(Centres(c.pos[k], c.valid[k], c.strength[k]), stripe)
                uv = uv[np.all(np.isfinite(uv), axis=1)]
                path = pending[i][0]
                new = [[path, stripe, f"{u:.4f}", f"{v:.4f}"] for u, v in uv]
                if sensor is not None and len(uv):
                    xyz = np.asarray(triangulate(sensor, uv, 0 if stripe == "h" else 1))
                    for row, p in zip(new, xyz, strict=True):
                        row.extend(f"{q:.4f}" for q in p)
                rows[i].extend(new)
    failed = 0
    for i, (path, _) in enumerate(pending):
        if rows[i]:
            writer.writerows(rows[i])
        else:
            print(f"cslx extract: {path}: no stripe found", file=sys.stderr)
            failed += 1
    pending.clear()
    return failed
