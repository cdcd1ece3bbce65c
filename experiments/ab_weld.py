"""Weld features of the tracking program, working tree against a git revision, in one process.

`cslx.runtime.weld.weld_features` is timed alone, as the tracking program calls it: its
inputs (both stripes' cleaned profiles and their masks; the default config passes no point
weights) are captured from `process_frame` in tracking mode (the default `PipelineConfig`,
MED in the bands, each video's state carried from frame to frame) on consecutive rendered
video frames. The revision's ``cslx`` is exported beside the working tree's
(`experiments.ab_tracking.export_revision`); both weld features run on every captured
frame and their outputs are compared field by field (found / junction flags must be
identical; the largest |Δ| of each float field over the frames where both found a bead);
then the calls are timed interleaved, alternating which goes first, medians over the calls.

    OPENBLAS_NUM_THREADS=1 python -m experiments.ab_weld --rev main --frames 200 \
        --videos sunny:0 sunny:555 glare:0 glare:555 --calls 400
"""

from __future__ import annotations

import argparse
import pathlib
import sys
import tempfile
import time

import numpy as np

from experiments.common import load_average

CACHE = pathlib.Path(tempfile.gettempdir()) / "cslx-ab-weld"


def pipeline_config(package: str, tracking: bool):
    """The default `PipelineConfig` of ``package``, or the tracker's `tracking_config()`."""
    import importlib

    config = importlib.import_module(f"{package}.runtime.pipeline_config")
    return config.tracking_config() if tracking else config.PipelineConfig()


def weld_inputs(nuisance: str, seed: int, n: int, tracking: bool) -> dict[str, np.ndarray]:
    """The weld features' inputs of ``n`` tracking-mode frames of a rendered video (cached);
    ``wh`` is NaN where the pipeline passes no weights."""
    CACHE.mkdir(exist_ok=True)
    path = CACHE / f"inputs_{nuisance}_{seed}_{n}_{'tracker' if tracking else 'default'}.npz"
    if path.exists():
        with np.load(path) as z:
            return dict(z)
    import jax.numpy as jnp

    from cslx import sim
    from cslx.runtime import pipeline
    from experiments.bench_speed import sensor32

    frames, _, _, _ = sim.render_video(n_frames=n, seed=seed, nuisance=nuisance)
    sensor = sensor32()
    config = pipeline_config("cslx", tracking)
    state = pipeline.init_state(config, sensor.camera.image_size)
    # the default config passes no point weights to the weld features (`_clip_weights`)
    assert config.clip_weight == 1.0 and config.edge_weight == 1.0
    out = {k: [] for k in ("Ph", "kh", "Pv", "kv", "wh", "found_h", "pos_h", "used_roi")}
    for rgb in frames:
        rgb = jnp.asarray(rgb)
        r, state = pipeline.process_frame(sensor, config, rgb, state)
        for key, value in (
            ("Ph", r.points_h),
            ("kh", jnp.isfinite(r.points_h[:, 0])),
            ("Pv", r.points_v),
            ("kv", jnp.isfinite(r.points_v[:, 0])),
            ("wh", jnp.full(r.points_h.shape[0], jnp.nan, jnp.float32)),
            ("found_h", r.feature_h.found),
            ("pos_h", r.feature_h.position),
            ("used_roi", r.used_roi),
        ):
            out[key].append(np.asarray(value))
    out = {k: np.stack(v) for k, v in out.items()}
    np.savez(path, **out)
    return out


def main(argv=None) -> None:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--rev", default="HEAD", help="git revision to compare against")
    ap.add_argument("--frames", type=int, default=200, help="consecutive frames per video")
    ap.add_argument("--videos", nargs="+", default=["sunny:0", "sunny:555"])
    ap.add_argument("--calls", type=int, default=400, help="timed calls per program")
    args = ap.parse_args(argv)
    import jax
    import jax.numpy as jnp

    from experiments.ab_tracking import export_revision

    data = []
    for video in args.videos:
        nuisance, seed = video.split(":")
        d = weld_inputs(nuisance, int(seed), args.frames, False)
        weighted = not np.all(np.isnan(d["wh"]))
        data += [
            (
                video,
                tuple(jnp.asarray(d[k][i]) for k in ("Ph", "kh", "Pv", "kv"))
                + ((jnp.asarray(d["wh"][i]),) if weighted else ()),
            )
            for i in range(args.frames)
        ]
        print(
            f"{video}: ROI on {d['used_roi'].mean():.0%} of frames, bead found on "
            f"{d['found_h'].mean():.0%}"
        )
    load_start = load_average()
    with tempfile.TemporaryDirectory() as tmp:
        export_revision(args.rev, pathlib.Path(tmp), "cslx_rev")
        sys.path.insert(0, tmp)
        import importlib

        runs = {}
        for name in ("cslx_rev", "cslx"):
            weld = importlib.import_module(f"{name}.runtime.weld")
            cfg = pipeline_config(name, False).weld
            runs[name] = jax.jit(
                lambda Ph, kh, Pv, kv, wh=None, weld=weld, cfg=cfg: weld.weld_features(
                    Ph, kh, Pv, kv, cfg, wh
                )
            )
        outs = {name: [jax.device_get(f(*x)) for _, x in data] for name, f in runs.items()}
        report = {}
        for (video, _), a, b in zip(data, outs["cslx_rev"], outs["cslx"], strict=True):
            for stripe, fa, fb in (("h", a[0], b[0]), ("v", a[1], b[1])):
                r = report.setdefault((video, stripe), {"frames": 0, "found": 0, "flip": 0})
                r["frames"] += 1
                r["found"] += int(fa.found)
                r["flip"] += int(fa.found != fb.found)
                for field in fa._fields:
                    if field == "found":
                        continue
                    x, y = np.asarray(getattr(fa, field)), np.asarray(getattr(fb, field))
                    if np.any(np.isnan(x) != np.isnan(y)):
                        r["nan_mismatch"] = r.get("nan_mismatch", 0) + 1
                    d = np.nanmax(np.abs(x.astype(float) - y.astype(float)), initial=0.0)
                    r[field] = max(r.get(field, 0.0), float(d))
            r = report.setdefault((video, "junction"), {"flip": 0, "true": 0})
            r["flip"] += int(a[2] != b[2])
            r["true"] += int(a[2])
        for key, r in report.items():
            print(key, {k: (f"{v:.3g}" if isinstance(v, float) else v) for k, v in r.items()})
        # timing: the captured frames in a cycle, interleaved
        times = {name: [] for name in runs}
        for f in runs.values():
            for _, x in data[:5]:
                jax.block_until_ready(f(*x))
        for k in range(args.calls):
            x = data[(k * 7) % len(data)][1]
            for name in list(runs)[:: 1 if k % 2 else -1]:
                t = time.perf_counter()
                jax.block_until_ready(runs[name](*x))
                times[name].append(time.perf_counter() - t)
    print(f"load {load_start} → {load_average()}; {args.calls} interleaved calls each")
    for name, label in (("cslx_rev", f"revision {args.rev}"), ("cslx", "working tree")):
        ms = np.asarray(times[name]) * 1e3
        print(
            f"{label:24s} median {np.median(ms):.3f} ms, p10 {np.percentile(ms, 10):.3f}, "
            f"p90 {np.percentile(ms, 90):.3f}"
        )


if __name__ == "__main__":
    main()
