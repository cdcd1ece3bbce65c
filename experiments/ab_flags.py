"""Tracking-mode frame time under two XLA_FLAGS settings, two processes run in lockstep.

XLA reads ``XLA_FLAGS`` once per process, so `experiments.ab_tracking` (two revisions in one
process) cannot compare flags. Here two worker processes, one per setting, each hold the
tracking mode of `experiments.bench_speed` (`process_frame`, consecutive rendered sunny
video frames, seed 0, state carried; ``--program tracking``: the tracker's
`tracking_config()`; ``cold``: every frame from `init_state`, the first pass's bands;
``fullframe``: from `init_state` with ``roi=False``, MED on the whole frame) and run one
frame at a time when told, alternating which goes first, so that both see the same load.
Reported: median, p10 and p90 per frame, the load, and the largest difference between the
two programs' outputs over the first frames. ``CSLX_XLA_SMALL_LOOPS=off`` in both, so
that `cslx.environment.configure` adds nothing to the flags given.

    OPENBLAS_NUM_THREADS=1 python -m experiments.ab_flags --calls 800 \\
        --b="--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold=1000000000"

``--one-thread b`` starts the second process's backend with one-thread pools instead
(`cslx.environment.one_thread_backend`; give both the same flags).
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import time

import numpy as np

from experiments.common import ROOT, load_average


def _worker(program: str) -> None:
    import jax

    from cslx.runtime import pipeline
    from experiments.bench_speed import sensor32, video_frames

    frames = [jax.numpy.asarray(f) for f in video_frames(24, 0)]
    sensor = sensor32()
    if program == "tracking":
        from cslx.runtime.tracker import tracking_config

        config = tracking_config()
    else:
        config = pipeline.PipelineConfig()
    state = pipeline.init_state(config, sensor.camera.image_size)
    for i in range(5):
        _, state = pipeline.process_frame(sensor, config, frames[i], state)
        jax.block_until_ready(state)
    print("ready", flush=True)
    outputs = []
    for line in sys.stdin:
        i = int(line)
        if i < 0:
            break
        if program in ("cold", "fullframe"):
            state = pipeline.init_state(config, sensor.camera.image_size)
        t = time.perf_counter()
        roi = program != "fullframe"
        result, state = pipeline.process_frame(sensor, config, frames[i], state, roi=roi)
        jax.block_until_ready((result, state))
        dt = time.perf_counter() - t
        if len(outputs) < 48:
            leaves = jax.tree_util.tree_leaves(result)
            outputs.append(np.concatenate([np.ravel(np.asarray(x, float)) for x in leaves]))
        print(dt, flush=True)
    print(json.dumps(np.stack(outputs).tolist()), flush=True)


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--a", default="", help="XLA_FLAGS of the first process (XLA's defaults)")
    ap.add_argument("--b", required=True, help="XLA_FLAGS of the second process")
    ap.add_argument("--calls", type=int, default=600, help="timed frames per process")
    ap.add_argument(
        "--program", choices=("pipeline", "tracking", "cold", "fullframe"), default="pipeline"
    )
    ap.add_argument(
        "--one-thread",
        choices=("a", "b"),
        help="start that process's backend with one-thread pools (CSLX_ONE_THREAD=1, "
        "cslx.environment.one_thread_backend)",
    )
    ap.add_argument("--worker", help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.worker:
        _worker(args.worker)
        return
    from experiments.bench_speed import ping_pong

    procs = {}
    for name, flags in (("a", args.a), ("b", args.b)):
        env = dict(os.environ, XLA_FLAGS=flags, CSLX_XLA_SMALL_LOOPS="off")
        env["CSLX_ONE_THREAD"] = "1" if args.one_thread == name else ""
        env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
        procs[name] = subprocess.Popen(
            [sys.executable, "-m", "experiments.ab_flags", "--b=", "--worker", args.program],
            env=env,
            cwd=ROOT,
            stdin=subprocess.PIPE,
            stdout=subprocess.PIPE,
            text=True,
        )
    for p in procs.values():
        if p.stdout.readline().strip() != "ready":
            raise RuntimeError("a worker failed to start")
    load_start = load_average()
    times = {name: [] for name in procs}
    for k, i in enumerate(ping_pong(24, args.calls)):
        for name in list(procs)[:: 1 if k % 2 else -1]:
            procs[name].stdin.write(f"{i}\n")
            procs[name].stdin.flush()
            times[name].append(float(procs[name].stdout.readline()))
    outputs = {}
    for name, p in procs.items():
        p.stdin.write("-1\n")
        p.stdin.flush()
        outputs[name] = np.asarray(json.loads(p.stdout.readline()))
        p.wait()
    print(f"load {load_start} → {load_average()}; {args.program}: {args.calls} frames each")
    for name, flags in (("a", args.a), ("b", args.b)):
        ms = np.asarray(times[name]) * 1e3
        print(
            f"{flags or 'XLA defaults'}: median {np.median(ms):.2f} ms, "
            f"p10 {np.percentile(ms, 10):.2f}, p90 {np.percentile(ms, 90):.2f}"
        )
    a, b = outputs["a"], outputs["b"]
    print(
        f"outputs: max |difference| {np.nanmax(np.abs(a - b)):.3g}, "
        f"NaN mismatches {int(np.sum(np.isnan(a) != np.isnan(b)))}"
    )


if __name__ == "__main__":
    main()
