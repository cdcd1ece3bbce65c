"""`PipelineConfig.roi_med_alternate` (band MED's step on one band a frame) against every frame.

Per development video seed (sunny, `experiments.bench_speed.video_frames`), tracking mode
with MED in the bands is carried over the frames twice, with and without the alternation,
and compared: on every third frame each run's band centres against the cold full-frame MED
of the same frame (worst |median band − full| over the frames and both stripes, the goal
of issue 13 being 0.05 px) and against the ground truth (median |centre − truth|), and the
two runs' centres against each other (median and largest |difference| over the centres
both found, and how many centres only one found); then the robot's `Tracker` with
``config=PipelineConfig(roi_med_alternate=...)`` on the same frames (largest |difference|
of the filtered offset, mm, and heading, deg). Last, both tracking modes timed on seed 0,
each with its own carried state, calls interleaved (median, p10, paired median).

    OPENBLAS_NUM_THREADS=1 python -m experiments.band_alternate --seeds 0 1 555 --calls 400

``--sequences SEED ...`` instead scores the `Tracker` with MED in the bands, both settings,
on development approaches to a T (`experiments.tracking_sequences`'s scenes and scores):

    python -m experiments.band_alternate --sequences 7301 7302 7305 7530 7531
"""

from __future__ import annotations

import argparse
import logging
import time

import numpy as np

from experiments.bench_speed import ping_pong, sensor32, video_frames
from experiments.common import load_average


def carried(sensor, config, frames):
    """Tracking-mode results of every frame, the state carried."""
    from cslx.runtime import pipeline

    st = pipeline.init_state(config, sensor.camera.image_size)
    out = []
    for f in frames:
        r, st = pipeline.process_frame(sensor, config, f, st)
        out.append(r)
    return out


def agreement(sensor, config, results, frames, truth):
    """(worst |median band − full| px, median |centre − truth| px) on every third frame."""
    from cslx.runtime import pipeline

    st0 = pipeline.init_state(config, sensor.camera.image_size)
    worst, errs = 0.0, []
    for i in range(0, len(frames), 3):
        full, _ = pipeline.process_frame(sensor, config, frames[i], st0, roi=False)
        for s, gt in (("h", truth["h_v"][i]), ("v", truth["v_u"][i])):
            c, cf = getattr(results[i], f"centres_{s}"), getattr(full, f"centres_{s}")
            both = np.asarray(c.valid & cf.valid)
            d = np.median(np.asarray(c.pos)[both] - np.asarray(cf.pos)[both])
            worst = max(worst, abs(float(d)))
            errs.append(np.nanmedian(np.abs(np.asarray(c.pos) - gt)))
    return worst, float(np.median(errs))


def robot(sensor, config, frames):
    """(offset mm, heading deg) of the `Tracker` on each frame."""
    from cslx.runtime.tracker import Tracker

    t = Tracker(sensor, config=config, log=logging.getLogger("band_alternate"))
    obs = [t.step(np.asarray(f)) for f in frames]
    return np.asarray([[o.offset_mm, o.heading_deg] for o in obs], float)


def sequences(configs, seeds, cache) -> int:
    """Per approach (seed, placement, nuisance): the issue-12 scores of the `Tracker` with
    each configuration (offset error mean / max mm, heading error mean °, T recall % / false
    T frames), then their means over the runs."""
    import pathlib

    from cslx.runtime.tracker import Tracker
    from cslx.sensor import default_sensor
    from experiments import tracking_sequences as ts

    trackers = {
        k: Tracker(default_sensor(), config=c, log=logging.getLogger("band_alternate"))
        for k, c in configs.items()
    }
    got = {k: [] for k in configs}
    for seed in seeds:
        for placement in ts.PLACEMENTS:
            for nuisance in ("sunny", "clean", "shadow"):
                seq = ts.make_sequence(seed, nuisance, placement, 48, pathlib.Path(cache))
                text = []
                for k, t in trackers.items():
                    s = ts.score(ts.run_tracker(t, seq), seq)
                    got[k].append(s)
                    text.append(
                        f"alternate={k} {s['offset_mean_mm']:.3f} / {s['offset_max_mm']:.3f} "
                        f"{s['heading_mean_deg']:.3f}° T {s['t_recall_pct']:.0f} / {s['t_false']}"
                    )
                print(seed, placement, nuisance, " | ".join(text), flush=True)
    for k, rows in got.items():
        off = np.mean([r["offset_mean_mm"] for r in rows])
        hd = np.mean([r["heading_mean_deg"] for r in rows])
        print(f"alternate={k}: {len(rows)} runs, offset mean {off:.4f} mm, heading {hd:.3f}°")
    return 0


def main(argv=None) -> int:
    import jax

    from cslx.runtime import pipeline
    from cslx.sensor import default_sensor

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="+", default=[0, 1, 555])
    p.add_argument("--frames", type=int, default=24)
    p.add_argument("--calls", type=int, default=400)
    p.add_argument(
        "--sequences",
        type=int,
        nargs="*",
        metavar="SEED",
        help="instead: the Tracker with MED in the bands on these development approaches "
        "of experiments.tracking_sequences (both placements; sunny, clean, shadow)",
    )
    p.add_argument("--cache", default="/tmp/cslx-tracking-sequences/sequences")
    a = p.parse_args(argv)
    sensor = sensor32()
    configs = {alt: pipeline.PipelineConfig(roi_med_alternate=alt) for alt in (False, True)}
    if a.sequences:
        return sequences(configs, a.sequences, a.cache)
    for seed in a.seeds:
        frames, truth = video_frames(a.frames, seed, with_truth=True)
        res = {k: carried(sensor, c, frames) for k, c in configs.items()}
        for k, c in configs.items():
            worst, err = agreement(sensor, c, res[k], frames, truth)
            print(f"seed {seed} alternate={k}: worst |median band − full| {worst:.4f} px, "
                  f"median |centre − truth| {err:.4f} px", flush=True)  # fmt: skip
        d, only = [], 0
        for r0, r1 in zip(res[False], res[True], strict=True):
            for s in ("h", "v"):
                c0, c1 = getattr(r0, f"centres_{s}"), getattr(r1, f"centres_{s}")
                v0, v1 = np.asarray(c0.valid), np.asarray(c1.valid)
                only += int(np.sum(v0 != v1))
                d.append(np.abs(np.asarray(c0.pos) - np.asarray(c1.pos))[v0 & v1])
        d = np.concatenate(d)
        tr = {k: robot(default_sensor(), c, frames) for k, c in configs.items()}
        dt = np.abs(tr[True] - tr[False])
        print(f"seed {seed}: centres alternate − every frame median {np.median(d):.2e} px, "
              f"max {d.max():.3f} px, found by one only {only} of {d.size + only}; Tracker "
              f"max |Δ offset| {np.nanmax(dt[:, 0]):.4f} mm (median {np.nanmedian(dt[:, 0]):.2e}, "
              f"over 0.1 mm on {int(np.sum(dt[:, 0] > 0.1))} of {len(dt)} frames), |Δ heading| "
              f"{np.nanmax(dt[:, 1], initial=0.0):.4f} deg", flush=True)  # fmt: skip
    if a.calls == 0:
        return 0
    frames = [jax.numpy.asarray(f) for f in video_frames(a.frames, 0)]
    states = {}
    for k, c in configs.items():
        st = pipeline.init_state(c, sensor.camera.image_size)
        for f in frames[:5]:
            _, st = pipeline.process_frame(sensor, c, f, st)
        states[k] = st
    load = load_average()
    ts = {k: [] for k in configs}
    for n, i in enumerate(ping_pong(len(frames), a.calls)):
        for k in list(configs)[:: 1 if n % 2 else -1]:
            t = time.perf_counter()
            r, states[k] = pipeline.process_frame(sensor, configs[k], frames[i], states[k])
            jax.block_until_ready((r, states[k]))
            ts[k].append(1e3 * (time.perf_counter() - t))
    print(f"load {load} → {load_average()}; {a.calls} interleaved frames each")
    for k, v in ts.items():
        print(f"alternate={k}: median {np.median(v):.3f} ms, p10 {np.percentile(v, 10):.3f}")
    paired = np.asarray(ts[True]) - np.asarray(ts[False])
    print(f"paired (alternate − every frame) median {np.median(paired):+.3f} ms")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
