"""XLA CPU flags against the tracking-mode frame time and the tracker's start-up, in one run.

Each flag set runs in its own process (XLA reads ``XLA_FLAGS`` once, when the backend starts):
the tracking mode of `experiments.bench_speed` (`process_frame` with the default
`PipelineConfig`, MED in the bands, consecutive sunny video frames, seed 0, state carried,
median of the timed calls), the size of that program (StableHLO operations and
while loops of the traced program), and the tracker's start-up from a warm compile cache
(`bench_speed._worker_compile`, its own cache per flag set: wall and CPU time). The flag
sets are visited in rounds (round-robin), so that the machine's load drifts over all of
them alike; the table gives the median over rounds. The persistent compile cache is keyed
by the flags, so a later round reloads the program instead of compiling it.

    OPENBLAS_NUM_THREADS=1 python -m experiments.speed_flags --rounds 2 --out /tmp/flags.md
"""

from __future__ import annotations

import argparse
import json
import os
import resource
import subprocess
import sys
import tempfile
import time

import numpy as np

from experiments.common import RESULTS, ROOT, load_average, timeit

#: Flag sets tried (name → XLA_FLAGS); "" is XLA's default.
FLAGS = {
    "default": "",
    "eigen single-threaded": "--xla_cpu_multi_thread_eigen=false",
    "no XNNPACK/YNNPACK fusions": "--xla_cpu_experimental_xnn_fusion_type= "
    "--xla_cpu_experimental_ynn_fusion_type=",
    "concurrency-optimised scheduler": "--xla_cpu_enable_concurrency_optimized_scheduler=true",
    "one codegen split": "--xla_cpu_parallel_codegen_split_count=1",
    "fast min/max": "--xla_cpu_enable_fast_min_max=true",
    "small loops in one function (cslx.environment)": "--xla_backend_extra_options="
    "xla_cpu_small_while_loop_byte_threshold=1000000000",
}


def _worker(calls: int, cache: str) -> dict:
    """One flag set, in this process: tracking-mode time and the program's HLO size."""
    import jax

    jax.config.update("jax_compilation_cache_dir", cache)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    from cslx.runtime import pipeline
    from experiments.bench_speed import _block, ping_pong, sensor32, video_frames

    frames = video_frames(24, 0)
    sensor = sensor32()
    config = pipeline.PipelineConfig()
    state = pipeline.init_state(config, sensor.camera.image_size)
    t = time.perf_counter()
    _, state = pipeline.process_frame(sensor, config, frames[0], state)
    _block(state)
    first_s = time.perf_counter() - t
    # the size of the traced program (StableHLO before XLA's passes; the flags act after)
    text = (
        jax.jit(lambda f, st: pipeline.process_frame(sensor, config, f, st))
        .lower(frames[0], state)
        .as_text()
    )
    size = dict(
        stablehlo_ops=text.count(" = stablehlo."), stablehlo_while=text.count("stablehlo.while")
    )
    holder = {"state": state, "roi": []}

    def track(i):
        res, holder["state"] = pipeline.process_frame(sensor, config, frames[i], holder["state"])
        _block((res, holder["state"]))
        holder["roi"].append(bool(res.used_roi))

    r = timeit(track, ping_pong(len(frames), calls + 10), calls, 60.0)
    return dict(
        tracking_ms=r["time_ms"],
        tracking_p90_ms=r["p90_ms"],
        roi_fraction=float(np.mean(holder["roi"])),
        first_call_s=first_s,
        **size,
    )


def _run(args: list[str], flags: str) -> dict:
    # CSLX_XLA_SMALL_LOOPS=off: `configure` adds nothing, each set runs its own flags alone
    env = dict(os.environ, XLA_FLAGS=flags, CSLX_XLA_SMALL_LOOPS="off")
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    before = resource.getrusage(resource.RUSAGE_CHILDREN)
    t = time.perf_counter()
    proc = subprocess.run(args, capture_output=True, text=True, env=env, timeout=1800)
    wall = time.perf_counter() - t
    after = resource.getrusage(resource.RUSAGE_CHILDREN)
    if proc.returncode != 0:
        raise RuntimeError(f"{args} with XLA_FLAGS={flags!r} failed:\n{proc.stderr[-3000:]}")
    out = json.loads(proc.stdout.strip().splitlines()[-1])
    out["process_wall_s"] = wall
    out["process_cpu_s"] = (after.ru_utime - before.ru_utime) + (after.ru_stime - before.ru_stime)
    return out


def main(rounds: int, calls: int, only: list[str] | None, out: str) -> None:
    names = [n for n in FLAGS if not only or n in only]
    load_start = load_average()
    caches = {n: tempfile.mkdtemp(prefix="cslx-flags-") for n in names}
    rows: dict[str, list[dict]] = {n: [] for n in names}
    for r in range(rounds):
        for n in names:
            here = [sys.executable, __file__]
            track = _run([*here, "--worker", str(calls), caches[n]], FLAGS[n])
            start = _run(
                [sys.executable, "-m", "experiments.bench_speed", "--worker-compile", caches[n]],
                FLAGS[n],
            )
            row = dict(
                track, start_s=start["start_to_first_frame_s"], start_cpu_s=start["process_cpu_s"]
            )
            row["load"] = os.getloadavg()[0]
            rows[n].append(row)
            print(f"round {r} {n:32s} {json.dumps(row)}", flush=True)
    lines = [
        "# XLA CPU flags: tracking mode and start-up (experiments/speed_flags.py)",
        "",
        f"Load average at the start {load_start}, at the end {load_average()} "
        f"({os.cpu_count()} cores); {rounds} rounds, {calls} timed tracking calls each; "
        "medians over rounds. Start-up: `bench_speed._worker_compile` from a warm cache "
        "(the first round compiles, so it is left out when there are more rounds).",
        "",
        "| flags | tracking ms | start-up s | start-up CPU s |",
        "|---|---|---|---|",
    ]
    for n in names:
        rs = rows[n]
        warm = rs[1:] if len(rs) > 1 else rs
        med = lambda k, rs=rs: float(np.median([x[k] for x in rs]))  # noqa: E731
        wmed = lambda k, warm=warm: float(np.median([x[k] for x in warm]))  # noqa: E731
        lines.append(
            f"| {n} (`{FLAGS[n] or '—'}`) | {med('tracking_ms'):.2f} | "
            f"{wmed('start_s'):.2f} | {wmed('start_cpu_s'):.2f} |"
        )
    size = rows[names[0]][0]
    lines += [
        "",
        f"The tracking program (traced, before XLA's passes): {size['stablehlo_ops']} StableHLO "
        f"operations, {size['stablehlo_while']} while loops.",
    ]
    text = "\n".join(lines) + "\n"
    print(text)
    os.makedirs(os.path.dirname(os.path.abspath(out)), exist_ok=True)
    with open(out, "w") as f:
        f.write(text)


def _cli(argv=None):
    p = argparse.ArgumentParser(description=__doc__)
    p.add_argument("--rounds", type=int, default=3)
    p.add_argument("--calls", type=int, default=150)
    p.add_argument("--only", nargs="+", help="flag-set names (keys of FLAGS)")
    p.add_argument("--out", default=str(RESULTS / "speed_flags.md"))
    p.add_argument("--worker", nargs=2, metavar=("CALLS", "CACHE"), help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker:
        print(json.dumps(_worker(int(a.worker[0]), a.worker[1])))
        return
    main(a.rounds, a.calls, a.only, a.out)


if __name__ == "__main__":
    _cli()
