"""Tracking-mode frame time of the working tree against a git revision, in one process.

The machine is shared and its load drifts, so a speed change is judged only against the
code before it, timed in the same process with the calls interleaved: the revision's
``cslx`` package is exported (`git archive`) into a temporary folder under another name and
imported beside the working tree's. Both run the tracking mode of `experiments.bench_speed`
(`process_frame` with the default `PipelineConfig`, MED in the bands, consecutive rendered
sunny video frames, seed 0, each its own state carried from frame to frame), alternating
which goes first. Reported: median, p10 and p90 per frame, the median process CPU time
per frame (all threads; less sensitive to the other users of a loaded machine than the wall
time, as a second opinion), the load, and the largest
difference between the two programs' outputs over the first frames (0 when the change
keeps the outputs bit for bit).

``--program`` picks what is timed: ``pipeline`` (the above, the default), ``tracking`` (the
same `process_frame` with the tracker's `tracking_config()`: no MED, domed clipped-core
fill), ``fullframe`` (the cold full frame of `experiments.bench_speed`: `process_frame` with
``roi=False`` from `init_state` every frame, MED on the whole frame from the cold start; each
call starts from the same initial state) or ``tracker`` (`Tracker.step` on NumPy frames,
the robot's loop end to end: its one compiled step, the transfers to the host and the
Kalman filter; compared outputs: the step's per-frame values, ``Observation.raw``, and the
filtered offset and heading); ``tracker-med`` the same `Tracker` with
``config=PipelineConfig()`` (MED in the bands, as `experiments.bench_speed` times it). Also
reported: the median of the paired differences (the two calls of a frame run back to back).

    OPENBLAS_NUM_THREADS=1 python -m experiments.ab_tracking --rev HEAD~1 --calls 300
    OPENBLAS_NUM_THREADS=1 python -m experiments.ab_tracking --rev main --program tracker
    OPENBLAS_NUM_THREADS=1 python -m experiments.ab_tracking --rev main --program fullframe
"""

from __future__ import annotations

import argparse
import importlib
import io
import pathlib
import subprocess
import sys
import tarfile
import tempfile
import time

import numpy as np

from experiments.bench_speed import ping_pong, sensor32, video_frames
from experiments.common import ROOT, load_average


def export_revision(rev: str, folder: pathlib.Path, name: str) -> None:
    """``cslx`` of git revision ``rev`` as the package ``name`` under ``folder``."""
    tar = subprocess.run(
        ["git", "archive", rev, "cslx"], cwd=ROOT, check=True, capture_output=True
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(tar)) as archive:
        archive.extractall(folder, filter="data")
    (folder / "cslx").rename(folder / name)


def tracker(package: str, frame, program: str = "pipeline"):
    """(step, state) of the tracking mode of ``package`` after a few warm-up frames."""
    import jax

    if program in ("tracker", "tracker-med"):
        return robot_tracker(package, frame, med=program == "tracker-med")
    pipeline = importlib.import_module(f"{package}.runtime.pipeline")
    sensor = sensor32(package)
    if program == "tracking":
        config = importlib.import_module(f"{package}.runtime.tracker").tracking_config()
    else:
        config = pipeline.PipelineConfig()
    state = pipeline.init_state(config, sensor.camera.image_size)
    if program == "fullframe":

        def cold(rgb, state):
            result, _ = pipeline.process_frame(sensor, config, rgb, state, roi=False)
            return jax.block_until_ready(result), state

        for _ in range(3):
            cold(frame, state)
        return cold, state

    def step(rgb, state):
        result, state = pipeline.process_frame(sensor, config, rgb, state)
        return jax.block_until_ready((result, state))

    for _ in range(3):
        _, state = step(frame, state)
    return step, state


def robot_tracker(package: str, frame, med: bool = False):
    """(step, None) of ``package``'s `Tracker` (default settings; ``med``: with
    ``config=PipelineConfig()``, MED in the bands) after warm-up frames; the step returns
    the observation's numbers (raw values, offset, heading) as one array."""
    import logging

    runtime_tracker = importlib.import_module(f"{package}.runtime.tracker")
    sensor = importlib.import_module(f"{package}.sensor").default_sensor()
    pipeline = importlib.import_module(f"{package}.runtime.pipeline")
    config = pipeline.PipelineConfig() if med else None
    robot = runtime_tracker.Tracker(sensor, config=config, log=logging.getLogger("ab_tracking"))
    frame = np.asarray(frame)

    def step(rgb, state):
        obs = robot.step(rgb)
        values = [obs.offset_mm, obs.heading_deg, *obs.raw.values()]
        return np.asarray(values, float), state

    for _ in range(10):  # past the σ / colour checks of the first frames
        step(frame, None)
    return step, None


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="HEAD", help="git revision to compare against")
    ap.add_argument("--calls", type=int, default=300, help="timed frames per program")
    ap.add_argument("--frames", type=int, default=24, help="video frames (ping-pong)")
    ap.add_argument("--seed", type=int, default=0, help="video seed (bench_speed's)")
    ap.add_argument(
        "--program",
        choices=("pipeline", "tracking", "fullframe", "tracker", "tracker-med"),
        default="pipeline",
        help="process_frame with PipelineConfig() / with tracking_config() / cold with "
        "roi=False, or Tracker.step (default settings / with PipelineConfig())",
    )
    args = ap.parse_args(argv)
    import jax

    frames = video_frames(args.frames, args.seed)
    if args.program.startswith("tracker"):
        frames = [np.asarray(f) for f in frames]
    else:
        frames = [jax.numpy.asarray(f) for f in frames]
    load_start = load_average()
    with tempfile.TemporaryDirectory() as tmp:
        export_revision(args.rev, pathlib.Path(tmp), "cslx_rev")
        sys.path.insert(0, tmp)
        runs = {name: tracker(name, frames[0], args.program) for name in ("cslx_rev", "cslx")}
        states = {name: state for name, (_, state) in runs.items()}
        times = {name: [] for name in runs}
        cpu = {name: [] for name in runs}
        outputs = {name: [] for name in runs}
        for k, i in enumerate(ping_pong(len(frames), args.calls)):
            for name in list(runs)[:: 1 if k % 2 else -1]:
                t, c = time.perf_counter(), time.process_time()
                result, states[name] = runs[name][0](frames[i], states[name])
                times[name].append(time.perf_counter() - t)
                cpu[name].append(time.process_time() - c)
                if k < 2 * len(frames):
                    leaves = jax.tree_util.tree_leaves(result)
                    outputs[name].append(np.concatenate([np.ravel(x) for x in leaves]))
    pairs = list(zip(outputs["cslx_rev"], outputs["cslx"], strict=True))
    if all(a.shape == b.shape for a, b in pairs):
        diff = max(float(np.nanmax(np.abs(a.astype(float) - b.astype(float)))) for a, b in pairs)
        nan_mismatch = sum(
            int(np.sum(np.isnan(a.astype(float)) != np.isnan(b.astype(float)))) for a, b in pairs
        )
    else:  # the two programs return different outputs (a field added or removed)
        diff, nan_mismatch = float("nan"), -1
    print(
        f"load {load_start} → {load_average()}; {args.program}: {args.calls} interleaved "
        "frames each"
    )
    for name, label in (("cslx_rev", f"revision {args.rev}"), ("cslx", "working tree")):
        ms = np.asarray(times[name]) * 1e3
        print(
            f"{label:24s} median {np.median(ms):.2f} ms, p10 {np.percentile(ms, 10):.2f}, "
            f"p90 {np.percentile(ms, 90):.2f}; process CPU median "
            f"{np.median(cpu[name]) * 1e3:.2f} ms"
        )
    # the two calls of one frame ran back to back: their difference cancels most of the
    # load's drift (median of the paired differences, and its spread over the frames)
    paired = (np.asarray(times["cslx"]) - np.asarray(times["cslx_rev"])) * 1e3
    q25, q50, q75 = np.percentile(paired, [25, 50, 75])
    print(
        f"paired (working tree − revision): median {q50:+.3f} ms, quartiles {q25:+.3f} / "
        f"{q75:+.3f}; working tree faster in {np.mean(paired < 0):.0%} of the frames"
    )
    if nan_mismatch < 0:
        print("outputs: not compared (the two programs return different fields)")
    else:
        print(f"outputs: max |difference| {diff:.3g}, NaN mismatches {nan_mismatch}")


if __name__ == "__main__":
    main()
