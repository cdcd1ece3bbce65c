"""`PipelineConfig.roi_lag_stride` against agreement and time (issue 13), in one process.

For each stride, tracking mode is carried over 24 consecutive sunny video frames
(`experiments.bench_speed.video_frames`) and compared, on every third frame, with the cold
full-frame MED of the same frame: the worst |median band − full| over the frames and both
stripes, and the median |centre − truth|. Then every stride's tracking mode is timed on the
video of seed 0, each with its own carried state, the calls interleaved (the order reversed
every other frame) so that the machine's load falls on all alike; medians after 20 calls.

    OPENBLAS_NUM_THREADS=1 python -m experiments.lag_stride --strides 2 4 8 --seeds 0 1 555
"""

from __future__ import annotations

import argparse
import time

import numpy as np

from experiments.bench_speed import ping_pong, sensor32, video_frames


def agreement(sensor, config, seed: int, n: int = 24) -> tuple[float, float]:
    """(worst |median band − full| px, median |centre − truth| px) over every third frame."""
    from cslx.runtime import pipeline

    frames, truth = video_frames(n, seed, with_truth=True)
    st0 = pipeline.init_state(config, sensor.camera.image_size)
    st, worst, errs = st0, 0.0, []
    for i in range(n):
        tracked, st = pipeline.process_frame(sensor, config, frames[i], st)
        if i % 3:
            continue
        full, _ = pipeline.process_frame(sensor, config, frames[i], st0, roi=False)
        for s, gt in (("h", truth["h_v"][i]), ("v", truth["v_u"][i])):
            c, cf = getattr(tracked, f"centres_{s}"), getattr(full, f"centres_{s}")
            both = np.asarray(c.valid & cf.valid)
            d = np.median(np.asarray(c.pos)[both] - np.asarray(cf.pos)[both])
            worst = max(worst, abs(float(d)))
            errs.append(np.nanmedian(np.abs(np.asarray(c.pos) - gt)))
    return worst, float(np.median(errs))


def timing(sensor, configs: dict, calls: int = 400) -> dict[int, tuple[float, float]]:
    """Median and p10 (ms) of each config's tracking frame, calls interleaved."""
    import jax

    from cslx.runtime import pipeline

    frames = video_frames(24, 0)
    states = {}
    for k, c in configs.items():
        states[k] = pipeline.process_frame(
            sensor, c, frames[0], pipeline.init_state(c, sensor.camera.image_size)
        )[1]
    keys = list(configs)
    ts = {k: [] for k in keys}
    for n, i in enumerate(ping_pong(24, calls)):
        for k in keys if n % 2 else keys[::-1]:
            t = time.perf_counter()
            r, states[k] = pipeline.process_frame(sensor, configs[k], frames[i], states[k])
            jax.block_until_ready((r, states[k]))
            ts[k].append(time.perf_counter() - t)
    return {k: (1e3 * np.median(v[20:]), 1e3 * np.percentile(v[20:], 10)) for k, v in ts.items()}


def main(argv=None) -> int:
    from cslx.runtime import pipeline

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--strides", type=int, nargs="+", default=[2, 4, 8])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 555])
    p.add_argument("--calls", type=int, default=400)
    a = p.parse_args(argv)
    sensor = sensor32()
    configs = {k: pipeline.PipelineConfig(roi_lag_stride=k) for k in a.strides}
    for seed in a.seeds:
        for k, c in configs.items():
            worst, err = agreement(sensor, c, seed)
            print(f"seed {seed} stride {k}: worst |median band − full| {worst:.4f} px, "
                  f"median |centre − truth| {err:.4f} px", flush=True)  # fmt: skip
    for k, (med, p10) in timing(sensor, configs, a.calls).items():
        print(f"stride {k}: tracking mode median {med:.3f} ms, p10 {p10:.3f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
