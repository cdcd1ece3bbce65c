"""How the cost of the cslx pipeline grows: image size, MED filter length L, batch size.

- Image size: rendered 640×480 video frames resized (`cv2.resize`, area / cubic) to
  320×240, 640×480, 1280×720 and 1920×1080, with the camera's intrinsics scaled to match
  (the 16:9 sizes stretch the 4:3 scene; timing does not care). The stripe gets wider in
  pixels, so Steger's σ (2 px at 480 rows), the ROI band half-sizes (32 rows, 64 columns at
  640×480) and the band margin scale with the image; with fixed 640×480 settings the
  tracker lost its bands at 1280×720 on 90 % of frames (measured) and fell back to the
  full frame. Whole pipeline in tracking
  mode (warm MED, ROI bands of fixed size) and cold on the full frame (flat MED, L = 50 %
  of the segment, to convergence).
- Filter length: cold MED of the horizontal stripe on 640×480 for L from 16 to 480; time,
  fixed-point steps and time per step.
- Batch size: the archive path (`cslx.segmentation.shard.process_archive` of `extract`
  "med", horizontal stripe) for 1, 4, 16 frames per call, vectorised with vmap or mapped
  frame by frame (`lax.map`, the CPU default of `cslx.segmentation.shard`); frames/s.

Writes `results/bench_scaling.csv` and `results/bench_scaling.png`.

    OPENBLAS_NUM_THREADS=1 python -m experiments.bench_scaling [--quick]
"""

from __future__ import annotations

import argparse
import os
import time

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from experiments.bench_speed import ping_pong, sensor32, video_frames  # noqa: E402
from experiments.common import RESULTS, load_average, machine_record, timeit  # noqa: E402

SIZES = ((320, 240), (640, 480), (1280, 720), (1920, 1080))
LENGTHS = (16, 32, 64, 120, 240, 360, 480)
BATCHES = (1, 4, 16)
FULL = dict(video_frames=24, calls=60, slow_calls=10, budget_s=30.0)
QUICK = dict(video_frames=10, calls=20, slow_calls=3, budget_s=8.0)


def scaled_sensor(sensor, size):
    """The sensor with its camera intrinsics scaled to an image of `size` (w, h)."""
    import equinox as eqx

    from cslx.sensor.camera import Camera

    cam = sensor.camera
    w0, h0 = cam.image_size
    sx, sy = size[0] / w0, size[1] / h0
    new = Camera(cam.fx * sx, cam.fy * sy, cam.u0 * sx, cam.v0 * sy, cam.dist, tuple(size))
    return eqx.tree_at(lambda s: s.camera, sensor, new)


def main(quick: bool = False, seed: int = 0, out=RESULTS, **overrides) -> list[dict]:
    """Run the three sweeps; returns the rows (also written to results/bench_scaling.*)."""
    cfg = dict(QUICK if quick else FULL)
    cfg.update({k: v for k, v in overrides.items() if v is not None})
    load_start = load_average()
    import cv2
    import jax

    from cslx.provenance import provenance, write_csv
    from cslx.runtime import pipeline
    from cslx.segmentation import extract, med, shard
    from cslx.segmentation.colour import monochrome

    base = video_frames(cfg["video_frames"], seed)
    sensor0 = sensor32()
    n, slow, budget = cfg["calls"], cfg["slow_calls"], cfg["budget_s"]
    rows: list[dict] = []

    def add(sweep, x, name, res, **kw):
        row = dict(sweep=sweep, x=x, name=name, **res, **kw)
        rows.append(row)
        print(f"{sweep:6s} {x!s:10s} {name:30s} {res['time_ms']:10.2f} ms {kw}", flush=True)

    # --- image size -----------------------------------------------------------------------
    for size in SIZES:
        # The same scene at another resolution: the stripe's width in pixels, and so
        # Steger's σ, the ROI bands and their margin scale with the image.
        k = size[1] / 480
        config = pipeline.PipelineConfig(
            sigma=2.0 * k,
            roi_half_h=round(32 * k),
            roi_half_w=round(64 * size[0] / 640),
            roi_margin=round(8 * k),
        )
        interp = cv2.INTER_AREA if size[0] < 640 else cv2.INTER_CUBIC
        frames = np.stack([cv2.resize(f, size, interpolation=interp) for f in base])
        sensor = scaled_sensor(sensor0, size)
        state0 = pipeline.init_state(config, size)
        label = f"{size[0]}x{size[1]}"
        holder = {"state": state0, "roi": []}

        def track(i, frames=frames, sensor=sensor, holder=holder, config=config):
            r, holder["state"] = pipeline.process_frame(sensor, config, frames[i], holder["state"])
            jax.block_until_ready((r, holder["state"]))
            holder["roi"].append(bool(r.used_roi))

        t = time.perf_counter()
        track(0)
        compile_s = time.perf_counter() - t
        res = timeit(track, ping_pong(len(frames), n + 5), n, budget)
        add(
            "size",
            label,
            "tracking (ROI)",
            res,
            pixels=size[0] * size[1],
            sigma=config.sigma,
            roi_fraction=float(np.mean(holder["roi"])),
            compile_s=compile_s,
        )
        steps = []

        def cold(i, frames=frames, sensor=sensor, state0=state0, steps=steps, config=config):
            r, _ = pipeline.process_frame(sensor, config, frames[i], state0, roi=False)
            jax.block_until_ready(r)
            steps.append(np.asarray(r.med_steps).sum())

        t = time.perf_counter()
        cold(0)
        compile_s = time.perf_counter() - t
        steps.clear()
        res = timeit(cold, list(range(len(frames))), slow, budget)
        add(
            "size",
            label,
            "cold full frame",
            res,
            pixels=size[0] * size[1],
            med_steps=float(np.median(steps)),
            compile_s=compile_s,
        )

    # --- filter length L ------------------------------------------------------------------------
    monos = [monochrome(f, (1.0, -1.0, 0.0)) for f in base]
    for L in LENGTHS:
        steps = []

        def run_med(i, L=L, steps=steps):
            r = med.med(monos[i], axis=0, L=L)
            jax.block_until_ready(r)
            steps.append(int(r.steps))

        run_med(0)
        steps.clear()
        res = timeit(run_med, list(range(len(monos))), slow, budget)
        s = float(np.median(steps))
        add("L", L, "MED h cold (640x480)", res, med_steps=s, ms_per_step=res["time_ms"] / s)

    # --- batch size (archive path) ------------------------------------------------------------
    def one(rgb):
        c = extract(rgb, "med", stripe="h")
        return c.pos, c.valid

    for vmap_size, name in ((None, "archive: vmap"), (1, "archive: lax.map (CPU default)")):
        for B in BATCHES:
            if vmap_size == 1 and B == 1:
                continue  # the same program as vmap of one frame
            batch = base[np.arange(B) % len(base)]

            def run(_, batch=batch, B=B, vmap_size=vmap_size):
                return shard.process_archive(batch, one, batch_size=B, vmap_size=vmap_size)

            run(0)  # compile
            res = timeit(run, [0], max(3, slow), budget, warmup=1)
            add(
                "batch",
                B,
                name,
                res,
                frames_per_s=B / (res["time_ms"] / 1e3),
                ms_per_frame=res["time_ms"] / B,
            )

    machine = machine_record(load_start)
    load_end = machine["load_end"]
    prov = provenance(dict(cfg, quick=quick, seed=seed, **machine))
    os.makedirs(out, exist_ok=True)
    fields = ["sweep", "x", "name", "time_ms", "p90_ms", "calls", "pixels", "roi_fraction",
              "sigma", "compile_s", "med_steps", "ms_per_step", "frames_per_s",
              "ms_per_frame"]  # fmt: skip
    write_csv(os.path.join(out, "bench_scaling.csv"), rows, fields)
    _plot(rows, os.path.join(out, "bench_scaling.png"), prov, load_start, load_end)
    return rows


def _plot(rows, path, prov, load_start, load_end):
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    fig, ax = plt.subplots(1, 3, figsize=(14, 4.2))
    a = ax[0]
    for name, marker in (("tracking (ROI)", "o"), ("cold full frame", "s")):
        rs = [r for r in rows if r["sweep"] == "size" and r["name"] == name]
        px = np.array([r["pixels"] for r in rs]) / 1e6
        t = np.array([r["time_ms"] for r in rs])
        a.loglog(px, t, marker=marker, label=name)
        for r, x, y in zip(rs, px, t, strict=True):
            a.annotate(r["x"], (x, y), textcoords="offset points", xytext=(4, -10), fontsize=7)
    a.axhline(5, color="tab:blue", ls=":", lw=1, label="targets at 640×480: 5 / 50 ms")
    a.axhline(50, color="tab:orange", ls=":", lw=1)
    a.set_xlabel("megapixels")
    a.set_ylabel("ms per frame (median)")
    a.set_title("whole pipeline vs image size")
    a.legend(fontsize=8)
    a.grid(True, which="both", alpha=0.3)

    a = ax[1]
    rs = [r for r in rows if r["sweep"] == "L"]
    L = np.array([r["x"] for r in rs])
    a.plot(L, [r["time_ms"] for r in rs], "o-", label="cold MED (ms)")
    a.plot(L, [r["ms_per_step"] for r in rs], "s--", label="ms per fixed-point step")
    a.set_xlabel("MED filter length L (640×480, h stripe, M = 480)")
    a.set_ylabel("ms")
    a.set_title("MED vs filter length")
    b = a.twinx()
    b.plot(L, [r["med_steps"] for r in rs], "^:", color="tab:green", label="steps")
    b.set_ylabel("fixed-point steps", color="tab:green")
    b.set_ylim(0, 1.3 * max(r["med_steps"] for r in rs))
    a.set_ylim(0, None)
    a.legend(fontsize=8, loc="upper left")
    a.grid(True, alpha=0.3)

    a = ax[2]
    single = [r for r in rows if r["sweep"] == "batch" and r["x"] == 1]
    for name, marker in (("archive: vmap", "o-"), ("archive: lax.map (CPU default)", "s--")):
        rs = single + [r for r in rows if r["name"] == name and r["x"] > 1]
        B = np.array([r["x"] for r in rs])
        a.semilogx(B, [r["frames_per_s"] for r in rs], marker, base=2, label=name[9:])
    a.set_xlabel("frames per call (one device)")
    a.set_ylabel("frames / s")
    a.set_title("archive throughput (MED + Steger, h stripe)")
    a.legend(fontsize=8)
    a.grid(True, alpha=0.3)
    load = f"{load_start} → {load_end}"
    fig.suptitle(
        f"cslx scaling on {prov['cpu']} ({prov['cores']} cores, shared: load {load}); "
        f"git {prov['git']}; JAX {prov['versions'].get('jax')}, float32",
        fontsize=9,
    )
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)


def _cli(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--quick", action="store_true", help="fewer calls (smoke run)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(RESULTS))
    a = p.parse_args(argv)
    main(quick=a.quick, seed=a.seed, out=a.out)


if __name__ == "__main__":
    _cli()
