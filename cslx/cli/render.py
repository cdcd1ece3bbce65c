"""Render scenes with exact ground truth (docs/contracts.md, rendered data).

Writes PNG frames, the true calibration as DIR/sensor.json and DIR/gt.npz holding, with a
leading frame axis in the order of `frames`, `h_v` (F, W), `h_xyz` (F, W, 3), `v_u` (F, H),
`v_xyz` (F, H, 3) (NaN where a stripe is absent) plus the robot poses and the true weld
lines. `--scene calibration` writes checkerboard images without (`plain_*.png`) and with
(`laser_*.png`) the laser and the true board poses `R`, `t`, `object_points`,
`image_points`. The same arguments always give the same bytes. The data set is written
atomically (`cslx.files.atomic_directory`, `gt.npz` last): an interrupted run changes
nothing in DIR.
"""

from __future__ import annotations

import argparse
import sys
import time

NAME = "render"
HELP = "render frames (straight/cross weld, video, calibration board) with exact ground truth"


def add_arguments(parser: argparse.ArgumentParser) -> None:
    parser.add_argument(
        "--scene",
        choices=("straight", "cross", "video", "calibration"),
        default="straight",
        help="what to render (default straight)",
    )
    parser.add_argument(
        "--nuisance",
        choices=("clean", "sunny", "glare", "shadow", "mixed"),
        default="clean",
        help="illumination preset (default clean; mixed draws one per frame)",
    )
    parser.add_argument("--frames", type=int, default=10, help="number of frames or poses")
    parser.add_argument("--seed", type=int, default=0, help="random seed (default 0)")
    parser.add_argument("--out", required=True, metavar="DIR", help="output directory")
    parser.add_argument(
        "--laser-colour",
        "--laser-color",
        dest="laser_colour",
        choices=("red", "green"),
        default="red",
        help="laser colour: red (default) or 520 nm green",
    )
    parser.add_argument(
        "--power",
        type=float,
        default=None,
        help="laser power: peak red DN on the plate (default per preset, ≈230; >8000 clips "
        "the core to white)",
    )
    parser.add_argument(
        "--calib", metavar="FILE", help="render with this sensor (calibration JSON) instead"
    )


def _usage_error(msg: str) -> int:
    print(f"cslx render: {msg}", file=sys.stderr)
    return 2


def check_arguments(args: argparse.Namespace) -> str | None:
    """The first problem with the arguments (before JAX loads), or None."""
    import math

    from ..files import OutputPathError, check_output_dir

    if args.frames < 1:
        return f"--frames {args.frames}: must be at least 1"
    if args.power is not None and not (math.isfinite(args.power) and args.power > 0):
        return f"--power {args.power}: must be a positive number (peak red DN, e.g. 230)"
    try:
        check_output_dir(args.out)
    except OutputPathError as e:
        return f"--out {e}"
    return None


def run(args: argparse.Namespace) -> int:
    problem = check_arguments(args)
    if problem:
        return _usage_error(problem)
    import numpy as np

    from .. import sim as synth
    from ..sensor import CalibrationError, default_sensor, load_sensor

    try:
        sensor = load_sensor(args.calib) if args.calib else default_sensor()
        sensor.require_planes(2, "rendering (the simulated projector is a cross)")
    except CalibrationError as e:
        return _usage_error(str(e))
    t0 = time.perf_counter()
    if args.scene == "calibration":
        cal = synth.render_calibration(sensor, args.frames, args.seed, progress=True)
        n = len(cal["plain"])
        names = [f"plain_{i:03d}.png" for i in range(n)] + [f"laser_{i:03d}.png" for i in range(n)]
        images = np.concatenate([cal["plain"], cal["laser"]])
        gt = {k: cal[k] for k in ("R", "t", "object_points", "image_points")}
        gt["plain_frames"] = np.asarray(names[:n])
        gt["laser_frames"] = np.asarray(names[n:])
        synth.write_dataset(args.out, images, gt, sensor, names=names)
    elif args.scene == "video":
        frames, gt, poses, lines = synth.render_video(
            sensor,
            args.frames,
            args.seed,
            args.nuisance,
            progress=True,
            laser=args.laser_colour,
            power=args.power,
        )
        extra = {"poses": poses, **{k: v for k, v in lines.items() if k.startswith("weld_")}}
        synth.write_dataset(args.out, frames, gt, sensor, extra=extra)
    else:
        images, gt, sensor = synth.render_dataset(
            args.scene,
            args.nuisance,
            args.frames,
            args.seed,
            sensor,
            progress=True,
            laser=args.laser_colour,
            power=args.power,
        )
        synth.write_dataset(args.out, images, gt, sensor)
    dt = time.perf_counter() - t0
    print(f"wrote {args.frames} {args.scene} frame(s) to {args.out} in {dt:.1f} s", file=sys.stderr)
    return 0
