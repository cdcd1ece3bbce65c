"""Where a tracking frame's time goes: a `jax.profiler` trace of the compiled program, per kernel.

Runs the tracking mode of `experiments.bench_speed` (`process_frame` with the default
`PipelineConfig`, MED in the bands, consecutive rendered sunny video frames, seed 0, the
state carried from frame to frame; ``--program small``: the same pipeline compiled with the
tracker's outputs only, its summary, the two profiles and the state, as
`cslx.runtime.step_program` builds it), traces ``--frames`` calls and prints, per kernel
(an XLA thunk: a fusion, a library call, a loop compiled as one function), its
10th-percentile self time × its calls per frame (the load of a shared machine inflates
the median more than the low percentiles), grouped by the source operation XLA recorded
for it (``jit(_steger_centres)``, ``jit(_med)``, the weld features' loops ...). The sum of
the kernels is not the frame's wall time: XLA's CPU runtime runs independent kernels on its
two threads at once, and ``CommonPjRtLoadedExecutable::ExecuteHelperOnSingleDevice`` is the
host side of the call (the dispatch of ≈ 350 kernels a frame among it; it is grouped
with the copies XLA added, which carry no source operation).

What it showed (issue 13; 100 traced frames, load 9–11 on the 2-core CPU, so every figure
is inflated; p10 × calls, µs a frame): the band fills' two scans (`fill_clipped` compiled as
one function) 280 + 310, band MED's output products (`med_fft.shift_matrix`) 200 + 245 and
its 18 small FFTs 200 in all (10 of them on vectors of 41–144 samples), Steger's Gaussian
filters ≈ 460 and its eigen-decomposition and selection ≈ 545 (the 153-instruction fusion
computing the offset ``t`` of the 480×128 band the largest, 86), the weld features' two loops
220 + 165, the band of columns' transposes and the copies XLA adds to lay them out for the
fill 60 + 30 + 17 + 10, `frame_stats`'s strided slice 57, the host side of the call 520
(median 1465). The tracker's program (`--program small`) runs the same kernels (50 840
against 51 214 optimised HLO lines, kernel sums 3 382 against 3 303 µs in one run); called
flat, interleaved, 400 frames at load 11, it took 0.36 ms less wall (0.55 ms less CPU) than
`process_frame`, and the same program returning every `FrameResult` leaf (35 outputs
instead of 10) 0.10 ms less (CPU 0.13); again at load 8: −0.15 ms wall, −0.98 ms CPU against
+0.08 / −0.04: the outputs' handling on the host side, not the kernels.
In another run (300 interleaved frames, load 10) `Tracker.step` itself was 0.71 ms slower
than `process_frame`: its NumPy frame is copied to the device (`process_frame` on NumPy
frames +1.0 ms) and the Kalman filter runs in Python. bench_speed's rows (3.18 against
2.77 ms) were timed one after the other, not interleaved.

Acted on (issue 13, speed13p; 100 traced frames each, load 5–13, so inflated): band MED's
single-vector FFTs (a filter's spectrum, the short inverse transforms, the linear-phase sign)
as products with constant DFT matrices and its 8×8 linear-phase system by elimination in
two small loops (`cslx.segmentation.med_fft.filter_spectrum`, `irfft_head`, `spd_solve`:
no FFT, Cholesky or triangular-solve library call on the bands; 10 FFTs and 6 LAPACK calls a
frame gone, ≈ 85 µs p10 of them), and Steger's thresholds on the column maxima (two passes
over the ridge values instead of four, `cslx.segmentation.steger._select`): the ``jit(_med)``
group's p10 sum 690, 760, 793 → 565, 595, 652 µs (the three runs of each, not paired),
Steger's 866, 902, 948 → 726, 851, 885 µs, all kernels 3255, 3613, 3880 → 3041, 3157,
3429 µs. The Steger part was taken back (`c59fba6` reverted): its accepted point is the
pixel whose recomputed strength equals the column maximum exactly, and XLA computes the two
in different fusions; compiled at LLVM -O0 (the test session's level) the two differed in a
column, and Steger's gradient test (against finite differences) and the sharded-equals-vmap
test failed. It came back with the selection made exact (`cslx.reductions.first_argmax`:
the column's strongest candidate from one integer max reduction whose key carries the
index, no equality; the tracking program's outputs identical to `38c96b3`'s). The MED part
is kept (its profile sums above); alone, interleaved on the quiet
machine (``--rev 9911dcd``, 400 frames, load 0.3–1.1): median 3.43 → 3.37 ms, p10 3.16 →
3.11, paired −0.045 ms (quartiles −0.202 / +0.078), faster in 63 % of the frames. With both
parts,
`experiments.ab_tracking --rev main` at load 8–11 (600 interleaved frames): median
11.02 → 9.42 ms, p10 7.43 → 7.17, process CPU 8.10 → 7.71 ms, paired median −0.03 ms (the
load's quartiles ±3 ms: no wall-time figure on a quiet machine yet). Centres within 3e-5 px
(one float32 ulp at 256–512 px) of the FFT path's, band − full-frame agreement unchanged
(dev video seeds 0 / 1: 0.0204 / 0.0107 px). Tried and not kept: the fill's scan unrolled 4
or 8 steps a trip inside its one function (band cuts alone within ±0.04 ms), Steger's
eigenvector left unnormalised with its tests multiplied out (no gain alone), the band of
rows' output product as ``dot(X, Mᵀ)ᵀ`` (the same time). The host side grows with the
outputs: a trivial program returning 35 arrays took ≈ 170 µs a call against 12 µs for one
array of the same data (load 10), ≈ 4.5 µs an output, which is where `process_frame`'s 35
leaves cost beyond the tracker's 10.

    OPENBLAS_NUM_THREADS=1 python -m experiments.profile_tracking --frames 100
"""

from __future__ import annotations

import argparse
import collections
import gzip
import json
import pathlib
import re
import tempfile

import numpy as np

from experiments.bench_speed import ping_pong, sensor32, video_frames
from experiments.common import load_average


def op_names(hlo_text: str) -> dict[str, str]:
    """HLO instruction name → the source operation XLA recorded for it (``op_name``)."""
    names = {}
    for line in hlo_text.splitlines():
        m = re.match(r"\s*(?:ROOT )?%?([\w.\-]+) = .*?op_name=\"([^\"]*)\"", line)
        if m:
            names[m.group(1)] = m.group(2)
    return names


def self_times(trace: dict) -> dict[str, list[float]]:
    """Per event name, the durations (µs) less those of the events nested in it (same thread)."""
    by_thread = collections.defaultdict(list)
    for e in trace["traceEvents"]:
        if e.get("ph") == "X":
            by_thread[e["pid"], e["tid"]].append(e)
    out = collections.defaultdict(list)
    for events in by_thread.values():
        events.sort(key=lambda e: (e["ts"], -e["dur"]))
        stack, own = [], {}
        for e in events:
            while stack and stack[-1]["ts"] + stack[-1]["dur"] <= e["ts"]:
                stack.pop()
            own[id(e)] = e["dur"]
            if stack:
                own[id(stack[-1])] -= e["dur"]
            stack.append(e)
        for e in events:
            out[e["name"]].append(own[id(e)])
    return out


def group(op: str, depth: int) -> str:
    """The first ``depth`` parts of an op name, without the jit and `lax.cond` wrappers."""
    op = re.sub(r"^jit\([^)]*\)/", "", op)
    op = re.sub(r"(cond/branch_[01]_fun/)+", "", op)
    return "/".join(op.split("/")[:depth])


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--frames", type=int, default=100, help="traced frames")
    ap.add_argument("--seed", type=int, default=0, help="video seed (bench_speed's)")
    ap.add_argument("--program", choices=("process_frame", "small"), default="process_frame")
    ap.add_argument("--top", type=int, default=40, help="kernels listed")
    ap.add_argument("--depth", type=int, default=2, help="op-name parts per group")
    args = ap.parse_args(argv)
    import jax
    import jax.numpy as jnp

    from cslx.runtime import pipeline as pl

    frames = [jnp.asarray(f) for f in video_frames(24, args.seed)]
    sensor, config = sensor32(), pl.PipelineConfig()
    state0 = pl.init_state(config, sensor.camera.image_size)
    leaves0, treedef = jax.tree_util.tree_flatten(state0)

    def program(rgb, *state):
        result, new = pl.process_frame(sensor, config, rgb, treedef.unflatten(state))
        if args.program == "small":
            result = (pl.frame_summary(result), result.points_h, result.points_v)
        return (*jax.tree_util.tree_leaves(result), *jax.tree_util.tree_leaves(new))

    compiled = jax.jit(program).lower(frames[0], *leaves0).compile()
    names = op_names(compiled.as_text())
    n_state = len(leaves0)

    def step(i, state):
        out = jax.block_until_ready(compiled(frames[i], *state))
        return out[-n_state:]

    state = leaves0
    for i in range(5):
        state = step(i, state)
    load_start = load_average()
    options = jax.profiler.ProfileOptions()
    options.python_tracer_level = 0
    with tempfile.TemporaryDirectory() as tmp:
        with jax.profiler.trace(tmp, create_perfetto_trace=True, profiler_options=options):
            for i in ping_pong(len(frames), args.frames):
                state = step(i, state)
        path = next(pathlib.Path(tmp).rglob("*.trace.json.gz"))
        with gzip.open(path) as f:
            trace = json.load(f)
    n = args.frames
    rows = []
    for name, durations in self_times(trace).items():
        if name.startswith(("ThunkExecutor", "$")):
            continue
        d = np.asarray(durations)
        calls = len(d) / n
        op = group(names.get(name, "(no source op: runtime, copies)"), args.depth)
        rows.append((np.percentile(d, 10) * calls, np.median(d) * calls, calls, name, op))
    rows.sort(reverse=True)
    print(f"load {load_start} → {load_average()}; {args.program}, {n} traced frames")
    print(f"kernels: p10 × calls {sum(r[0] for r in rows):.0f} µs a frame, median × calls "
          f"{sum(r[1] for r in rows):.0f} µs")  # fmt: skip
    groups = collections.defaultdict(lambda: [0.0, 0.0, 0.0])
    for p10, med, calls, _, op in rows:
        groups[op][0] += p10
        groups[op][1] += med
        groups[op][2] += calls
    print("\n µs p10  µs median  kernels  source operation")
    for op, (p10, med, calls) in sorted(groups.items(), key=lambda g: -g[1][0])[: args.top]:
        print(f"{p10:8.1f} {med:10.1f} {calls:8.1f}  {op}")
    print("\n µs p10  µs median  calls  kernel  source operation")
    for p10, med, calls, name, op in rows[: args.top]:
        print(f"{p10:8.1f} {med:10.1f} {calls:6.1f}  {name[:44]:44s} {op}")


if __name__ == "__main__":
    main()
