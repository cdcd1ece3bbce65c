"""Band MED alone of the working tree against a git revision, in one process (issue 13).

`experiments.ab_tracking` times the whole tracking frame; this times only the MED of the two
tracking bands as the pipeline runs it (`cslx.segmentation.med.med` with the default
`PipelineConfig`'s ``L_roi``, ``roi_lag_stride``, linear phase and the lagged step, jitted
as a whole), on bands cut around the stripes of consecutive rendered sunny video frames
(bench_speed's seed 0), the filter converged on the first band. The revision's ``cslx`` is
exported beside the working tree's (`ab_tracking.export_revision`); the calls alternate
which goes first. Reported per band: median, p10, p90 and the median paired difference, and
the largest differences of the outputs and filters between the two.

    OPENBLAS_NUM_THREADS=1 python -m experiments.ab_band_med --rev main --calls 400
"""

from __future__ import annotations

import argparse
import importlib
import pathlib
import sys
import tempfile
import time

import numpy as np

from experiments.ab_tracking import export_revision
from experiments.bench_speed import ping_pong, video_frames
from experiments.common import load_average


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="HEAD", help="git revision to compare against")
    ap.add_argument("--calls", type=int, default=400, help="timed calls per band and program")
    ap.add_argument("--frames", type=int, default=8, help="video frames (ping-pong)")
    ap.add_argument("--seed", type=int, default=0, help="video seed (bench_speed's)")
    args = ap.parse_args(argv)
    import jax
    import jax.numpy as jnp

    from cslx.runtime.pipeline import PipelineConfig, colour_sum

    config = PipelineConfig()
    frames = video_frames(args.frames, args.seed)
    monos = [np.asarray(colour_sum(jnp.asarray(f), config.weights, jnp.float32)) for f in frames]
    hh, hw = 2 * config.roi_half_h, 2 * config.roi_half_w
    row0 = int(np.clip(np.argmax(monos[0].sum(1)) - hh // 2, 0, monos[0].shape[0] - hh))
    col0 = int(np.clip(np.argmax(monos[0].sum(0)) - hw // 2, 0, monos[0].shape[1] - hw))
    bands = {
        "h": ([jnp.asarray(m[row0 : row0 + hh]) for m in monos], 0),
        "v": ([jnp.asarray(m[:, col0 : col0 + hw]) for m in monos], 1),
    }
    load_start = load_average()
    with tempfile.TemporaryDirectory() as tmp:
        export_revision(args.rev, pathlib.Path(tmp), "cslx_rev")
        sys.path.insert(0, tmp)
        names = ("cslx_rev", "cslx")
        packages = {name: importlib.import_module(f"{name}.segmentation.med") for name in names}
        runs = {}
        for stripe, (band, axis) in bands.items():
            W = (
                packages["cslx"]
                .med(band[0], axis=axis, L=config.L_roi, symmetric=True, max_steps=60)
                .filter
            )
            results = {}
            for name, med in packages.items():
                fn = jax.jit(
                    lambda x, W, med=med, axis=axis: med.med(
                        x,
                        axis=axis,
                        L=config.L_roi,
                        init=W,
                        symmetric=config.roi_symmetric,
                        lag=True,
                        lag_stride=config.roi_lag_stride,
                    )
                )
                for f in band[:3]:
                    jax.block_until_ready(fn(f, W))
                runs[stripe, name] = (fn, band, W)
                results[name] = fn(band[1], W)
            a, b = results["cslx_rev"], results["cslx"]
            print(
                f"{stripe} band {band[0].shape}: outputs max |difference| "
                f"{float(jnp.max(jnp.abs(a.output - b.output))):.3g} (largest value "
                f"{float(jnp.max(jnp.abs(a.output))):.3g}), filters "
                f"{float(jnp.max(jnp.abs(a.filter - b.filter))):.3g}"
            )
        times = {key: [] for key in runs}
        keys = list(runs)
        for k, i in enumerate(ping_pong(len(frames), args.calls)):
            for key in keys[:: 1 if k % 2 else -1]:
                fn, band, W = runs[key]
                t = time.perf_counter()
                jax.block_until_ready(fn(band[i], W))
                times[key].append(time.perf_counter() - t)
    print(f"load {load_start} → {load_average()}; {args.calls} interleaved calls each")
    for stripe in bands:
        for name, label in (("cslx_rev", f"revision {args.rev}"), ("cslx", "working tree")):
            ms = np.asarray(times[stripe, name]) * 1e3
            print(
                f"{stripe} {label:24s} median {np.median(ms):.3f} ms, p10 "
                f"{np.percentile(ms, 10):.3f}, p90 {np.percentile(ms, 90):.3f}"
            )
        paired = np.asarray(times[stripe, "cslx"]) - np.asarray(times[stripe, "cslx_rev"])
        paired_ms = np.median(paired) * 1e3
        print(f"{stripe} paired (working tree − revision): median {paired_ms:+.3f} ms")


if __name__ == "__main__":
    main()
