"""Speed of the cslx pipeline and of its peers, on the same 640×480 frames, in one run.

One function per measured figure (median wall time after warm-up, every result blocked with
`jax.block_until_ready` or converted to NumPy; timing helpers in `experiments.common`):

- `bench_pipeline`: the whole per-frame pipeline (`cslx.runtime.pipeline.process_frame`:
  colour → MED on both stripes → Steger → triangulation → weld features) in tracking mode
  (consecutive video frames, state carried; MED in the bands, and without it as before
  issue 13), a cold frame (bands from the first pass, MED converged there), the cold full
  frame (MED from `PipelineConfig.start`, L = 240 / 320, to `PipelineConfig.tol`), both
  also as before (Table 2's flat start, tol 1e-4), the warm full frame and the tracker's `step`;
- `bench_band_agreement`: band centres (first-pass bands, and tracking carried over the
  video) against full-frame MED centres and the ground truth, for linear-phase band filters
  (the default) and free ones with the ridge or the correlation-peak delay (issue 13);
- `bench_archive`: `cslx.segmentation.med_bands.extract_frames`, the band MED that
  `cslx extract --method med` runs on batches, per frame, and its centres against
  full-frame MED and the truth;
- `bench_med_stages`: MED per stripe cold and warm, its precompute and one fixed-point
  iteration, Steger per stripe, and the NumPy/SciPy MED peer (`experiments.bench_peers`);
- `bench_tracking_pieces`: the pieces of the tracking path (colour as `x @ w` and as the
  pipeline's channel-weighted sum, band MED, band Steger, frame statistics, triangulation,
  weld features);
- `bench_baselines`: CM / LA / QA / AA (`cslx.segmentation.baselines`);
- `bench_filter_peers`: OpenCV Gaussian-derivative filters + NumPy Steger, scikit-image's
  Hessian eigenvalues, the PyPI package `ridge-detection` (1–3 frames);
- `bench_batch`: `process_batch` for 1, 4, 16 consecutive frames: frame by frame with MED
  warm-started from the previous frame (`lax.scan`, the CPU default), frame by frame from
  the cold start (`lax.map`), and vectorised (vmap, the old default);
- `bench_cli_extract`: `cslx extract --method med` end to end in a subprocess on an archive
  of PNG files (decoding and CSV writing included; start-up cancelled by a short run);
- `bench_compile_cache`, `bench_memory`: the tracker's start-up compile in fresh processes
  sharing a persistent compilation cache (timed from just before the process starts to its
  first frame, the median of 5 starts), and a long tracker run's memory.

Ratios peer / cslx are taken in the same run; the machine is shared and absolute times drift
with its load, which is recorded at the start and end.

Writes `results/bench_speed.csv` and `results/bench_speed.md`.

    OPENBLAS_NUM_THREADS=1 python -m experiments.bench_speed           # full run
    OPENBLAS_NUM_THREADS=1 python -m experiments.bench_speed --quick   # smoke run
"""

from __future__ import annotations

import argparse
import dataclasses
import gc
import json
import math
import os
import pathlib
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import dataclass, field

# OpenBLAS's threaded Cholesky stalls MED on this machine (cslx.segmentation.med docstring).
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

import numpy as np  # noqa: E402

from experiments.bench_peers import (  # noqa: E402
    gaussian_kernels,
    numpy_med_prepare,
    numpy_med_update,
    opencv_steger,
    ridge_detection_peer,
    skimage_hessian,
)
from experiments.common import RESULTS, ROOT, load_average, machine_record, timeit  # noqa: E402

SIGMA = 2.0
WEIGHTS = (1.0, -1.0, 0.0)  # R − G, the pipeline's default
FULL = dict(
    video_frames=24,
    calls=200,
    slow_calls=20,
    ridge_frames=2,
    long_frames=10_000,
    budget_s=60.0,
    cli_frames=240,
    agreement_frames=8,
)
QUICK = dict(
    video_frames=10,
    calls=100,
    slow_calls=5,
    ridge_frames=1,
    long_frames=600,
    budget_s=20,
    cli_frames=16,
    agreement_frames=3,
)
#: Frames of the short `cslx extract` run whose time (start-up, compile) is subtracted.
CLI_BASE_FRAMES = 8  # = cslx.cli.extract.MED_BATCH: both runs use the same compiled batch
#: Fresh processes timed at a start-up with a warm compile cache (their median is reported).
CACHED_STARTS = 5


# ------------------------------------------------------------------------------ helpers
def video_frames(n: int, seed: int, with_truth: bool = False):
    """Consecutive rendered video frames (sunny, the robot driving along a weld), cached;
    with the ground-truth centres (h_v, v_u) when ``with_truth``."""
    cache = pathlib.Path(tempfile.gettempdir()) / "cslx-bench"
    cache.mkdir(exist_ok=True)
    path = cache / f"video_{n}_{seed}_gt.npz"
    if not path.exists():
        from cslx import sim as synth

        frames, gt, _, _ = synth.render_video(n_frames=n, seed=seed, nuisance="sunny")
        np.savez(path, frames=frames, h_v=gt["h_v"], v_u=gt["v_u"])
    with np.load(path) as z:
        frames = z["frames"]
        truth = {"h_v": z["h_v"], "v_u": z["v_u"]}
    return (frames, truth) if with_truth else frames


def ping_pong(n: int, count: int) -> list[int]:
    """Frame indices 0..n−1..0..: a continuous motion for any number of tracking calls."""
    cycle = list(range(n)) + list(range(n - 2, 0, -1))
    return [cycle[i % len(cycle)] for i in range(count)]


def sensor32(package: str = "cslx"):
    """The default sensor in float32, from ``package`` (another name for a revision's cslx
    in `experiments.ab_tracking`)."""
    import importlib

    import jax
    import jax.numpy as jnp

    default_sensor = importlib.import_module(f"{package}.sensor").default_sensor
    return jax.tree_util.tree_map(
        lambda x: jnp.asarray(x, jnp.float32) if isinstance(x, jax.Array) else x,
        default_sensor(),
    )


@dataclass
class Bench:
    """What the measurements share: settings, frames, and the rows and facts they produce."""

    cfg: dict
    seed: int
    sensor: object
    frames: np.ndarray
    truth: dict
    monos: list
    rows: list = field(default_factory=list)
    extra: dict = field(default_factory=dict)
    stage: dict = field(default_factory=dict)

    @property
    def n(self) -> int:
        return self.cfg["calls"]

    @property
    def slow(self) -> int:
        return self.cfg["slow_calls"]

    @property
    def budget(self) -> float:
        return self.cfg["budget_s"]

    @property
    def F(self) -> int:
        return len(self.frames)

    def add(self, group: str, name: str, res: dict, **kw) -> dict:
        row = dict(group=group, name=name, **res, **kw)
        self.rows.append(row)
        t = row.get("time_ms", math.nan)
        print(f"{group:10s} {name:60s} {t:10.3f} ms  {kw}", flush=True)
        return row


def _gated_share(statuses: list[str]) -> float:
    """Share of `Tracker.step` calls whose bead failed the innovation gate (those calls also
    ran the gated frame's refit near the predicted line, `cslx.runtime.bead_near`)."""
    return round(sum(s == "bead rejected (gate)" for s in statuses) / max(len(statuses), 1), 3)


def _block(x):
    import jax

    return jax.block_until_ready(x)


# ----------------------------------------------------------------------- measurements
def bench_pipeline(b: Bench) -> None:
    """The whole per-frame program: tracking (MED in the bands, and without), cold frames."""

    from cslx.runtime import pipeline
    from cslx.runtime.tracker import Tracker

    sensor, frames = b.sensor, b.frames
    config = pipeline.PipelineConfig()
    state0 = pipeline.init_state(config, sensor.camera.image_size)
    t = time.perf_counter()
    r, s = pipeline.process_frame(sensor, config, frames[0], state0)
    _block((r, s))
    b.extra["compile_tracking_s"] = time.perf_counter() - t
    t = time.perf_counter()
    _block(pipeline.process_frame(sensor, config, frames[0], state0, roi=False))
    b.extra["compile_full_frame_s"] = time.perf_counter() - t
    order = ping_pong(b.F, b.n + 10)

    for key, label, cfg in (
        ("tracking", "tracking mode (MED in the bands, warm), process_frame", config),
        (
            "tracking_no_med",
            "tracking mode without MED in the bands (before issue 13)",
            pipeline.PipelineConfig(roi_med=False),
        ),
        (
            "tracking_whole_frame",
            "tracking mode, whole frame converted before the bands are cut (band_first=False)",
            pipeline.PipelineConfig(band_first=False, stats_stride=1),
        ),
    ):
        st = pipeline.init_state(cfg, sensor.camera.image_size)
        _, st = pipeline.process_frame(sensor, cfg, frames[0], st)
        holder = {"state": st, "roi": [], "steps": []}

        def track(i, cfg=cfg, holder=holder):
            res, holder["state"] = pipeline.process_frame(sensor, cfg, frames[i], holder["state"])
            _block((res, holder["state"]))
            holder["roi"].append(bool(res.used_roi))
            holder["steps"].append(np.asarray(res.med_steps))

        b.stage[key] = b.add(
            "pipeline",
            label,
            timeit(track, order, b.n, b.budget),
            roi_fraction=float(np.mean(holder["roi"])),
        )
        steps = np.asarray(holder["steps"])  # the mean: with `roi_med_alternate` 0.5 a band
        b.stage[key]["med_steps"] = f"h {np.mean(steps[:, 0]):.2g}, v {np.mean(steps[:, 1]):.2g}"

    holder = {"state": s, "steps": []}

    def track_full(i):
        res, holder["state"] = pipeline.process_frame(
            sensor, config, frames[i], holder["state"], roi=False
        )
        _block((res, holder["state"]))
        holder["steps"].append(np.asarray(res.med_steps))

    b.add(
        "pipeline",
        "warm full frame (warm MED, no ROI)",
        timeit(track_full, order, max(b.slow, b.n // 4), b.budget),
        med_steps=float(np.median(np.sum(holder["steps"], axis=1))),
    )
    # The tracker's frames that fail its innovation gate also run `bead_near`'s refit (≈ 2 ms):
    # the video turns onto the crossing weld and is replayed back and forth with the nominal
    # odometry, so many frames do; their share is recorded with each row.
    tracker = Tracker.from_calibration(sensor, log=lambda s: None)
    statuses: list[str] = []

    def tracked(robot):
        return lambda i: statuses.append(robot.step(frames[i]).status)

    res = timeit(tracked(tracker), order, b.n, b.budget)
    b.add(
        "pipeline",
        "Tracker.step (pipeline + host transfer + Kalman)",
        res,
        gated=_gated_share(statuses),
    )
    # The robot's loop with MED in the bands: the tracker built on the default PipelineConfig
    # (its compiled step closes over the sensor and settings; the tracker's own default,
    # `tracking_config`, runs no MED).
    with_med = Tracker.from_calibration(sensor, config, log=lambda s: None)
    statuses.clear()
    res = timeit(tracked(with_med), order, b.n, b.budget)
    b.stage["tracker_med"] = b.add(
        "pipeline",
        "Tracker.step with MED in the bands (config=PipelineConfig())",
        res,
        gated=_gated_share(statuses),
    )
    before = dataclasses.replace(config, start="flat", tol=1e-4)
    for key, label, roi, cfg in (
        ("cold_bands", "cold frame: bands from the first pass, MED converged there", True, config),
        ("cold_bands_before", "cold frame, first-pass bands, tol 1e-4 (before)", True, before),
        ("cold_full", "cold full frame (impulse start, tol 1e-2, L=240/320)", False, config),
        ("cold_full_before", "cold full frame, Table 2's flat start, tol 1e-4 (before)", False,
         before),
    ):  # fmt: skip
        steps, used = [], []
        st0 = pipeline.init_state(cfg, sensor.camera.image_size)

        def cold(i, roi=roi, steps=steps, used=used, cfg=cfg, st0=st0):
            res, _ = pipeline.process_frame(sensor, cfg, frames[i], st0, roi=roi)
            _block(res)
            steps.append(np.asarray(res.med_steps))
            used.append(bool(res.used_roi))

        row = b.add(
            "pipeline", label, timeit(cold, list(range(b.F)), max(b.slow, b.n // 4), b.budget)
        )
        cs = np.asarray(steps)
        row["med_steps"] = f"h {np.median(cs[:, 0]):.0f}, v {np.median(cs[:, 1]):.0f}"
        row["roi_fraction"] = float(np.mean(used))
        b.stage[key] = row


#: Band variants compared by `bench_band_agreement`: (key, label, PipelineConfig keywords).
BAND_VARIANTS = (
    ("symmetric", "linear-phase band filters (default)", {}),
    ("ridge", "free band filters, ridge delay (before)", {"roi_symmetric": False}),
    ("xcorr", "free band filters, correlation-peak delay", {"roi_symmetric": False,
                                                           "med_delay": "xcorr"}),
)  # fmt: skip


def bench_band_agreement(b: Bench) -> None:
    """Band centres vs full-frame MED centres (and the truth), per band-filter variant.

    The reference is the full frame with MED (cold, ``roi=False``). Two band runs: a cold
    frame with first-pass bands, and tracking carried over the whole video from frame 0
    (band filters warm-started frame after frame, so they converge as they do on the
    robot). Reported: the largest |median band − full| over the picked frames and both
    stripes, and the median |centre − truth|.
    """
    from cslx.runtime import pipeline

    sensor = b.sensor
    k = min(b.cfg["agreement_frames"], b.F)
    picks = set(np.linspace(0, b.F - 1, k).round().astype(int).tolist())
    for key, _, kw in BAND_VARIANTS:
        config = pipeline.PipelineConfig(**kw)
        state0 = pipeline.init_state(config, sensor.camera.image_size)
        worst = {"tracking": 0.0, "first pass": 0.0}
        err = {"full": [], "tracking": [], "first pass": []}
        st = state0
        for i in range(b.F):
            tracked, st = pipeline.process_frame(sensor, config, b.frames[i], st)
            if i not in picks:
                continue
            full, _ = pipeline.process_frame(sensor, config, b.frames[i], state0, roi=False)
            runs = {
                "tracking": tracked,
                "first pass": pipeline.process_frame(sensor, config, b.frames[i], state0)[0],
            }
            for stripe, gt in (("h", b.truth["h_v"][i]), ("v", b.truth["v_u"][i])):
                cf = getattr(full, f"centres_{stripe}")
                err["full"].append(np.nanmedian(np.abs(np.asarray(cf.pos) - gt)))
                for name, r in runs.items():
                    c = getattr(r, f"centres_{stripe}")
                    both = np.asarray(c.valid & cf.valid)
                    if both.any():
                        d = np.median(np.asarray(c.pos)[both] - np.asarray(cf.pos)[both])
                        worst[name] = max(worst[name], abs(float(d)))
                    err[name].append(np.nanmedian(np.abs(np.asarray(c.pos) - gt)))
        b.extra[f"agreement_{key}"] = dict(
            frames=len(picks),
            worst_tracking_px=worst["tracking"],
            worst_first_pass_px=worst["first pass"],
            **{f"median_err_{k.replace(' ', '_')}_px": float(np.median(v)) for k, v in err.items()},
        )
        print(f"agreement ({key}): {b.extra[f'agreement_{key}']}", flush=True)


def bench_archive(b: Bench) -> None:
    """Band MED for archives (`cslx.segmentation.med_bands.extract_frames`), in process.

    Batches of MED_BATCH frames, band filters carried from batch to batch as the command
    line does; time per frame, steps, bands used, and the centres against full-frame MED
    (the paper's method, ridge delay) and the truth.
    """
    import jax.numpy as jnp

    from cslx.cli.extract import MED_BATCH
    from cslx.segmentation import med, med_bands, steger

    cfg = med_bands.BandConfig(weights=WEIGHTS, sigma=SIGMA)
    F = b.F - b.F % MED_BATCH
    batches = [b.frames[i : i + MED_BATCH] for i in range(0, F, MED_BATCH)]
    holder = {"filters": med_bands.initial_filters(cfg), "steps": [], "band": []}

    def run(i):
        holder["filters"], res = med_bands.extract_frames(batches[i], holder["filters"], cfg)
        _block(res)
        holder["steps"].append([np.asarray(r.steps) for r in res])
        holder["band"].append([np.asarray(r.used_band) for r in res])
        return res

    res = timeit(run, list(range(len(batches))), max(b.slow, 8), b.budget)
    steps = np.concatenate([np.stack(s, 1) for s in holder["steps"]])
    used = np.concatenate([np.stack(u, 1) for u in holder["band"]])
    row = b.add(
        "archive",
        f"band MED + Steger, both stripes (med_bands.extract_frames, batch {MED_BATCH})",
        dict(res, time_ms=res["time_ms"] / MED_BATCH, p90_ms=res["p90_ms"] / MED_BATCH),
        med_steps=f"h {np.median(steps[:, 0]):.0f}, v {np.median(steps[:, 1]):.0f}",
        roi_fraction=float(np.mean(used)),
    )
    b.stage["archive"] = row
    # Accuracy on the first batch, from the flat start (what a new archive gets).
    _, (rh, rv) = med_bands.extract_frames(batches[0], med_bands.initial_filters(cfg), cfg)
    diffs, err_b, err_f = [], [], []
    for k in range(len(batches[0])):
        for axis, r, gt in ((0, rh, b.truth["h_v"][k]), (1, rv, b.truth["v_u"][k])):
            full = med.med(b.monos[k], axis=axis)
            cf = steger.steger_centres(full.output, sigma=SIGMA, axis=axis)
            pos, valid = np.asarray(r.centres.pos[k]), np.asarray(r.centres.valid[k])
            both = valid & np.asarray(cf.valid)
            diffs.append(abs(float(np.median(pos[both] - np.asarray(cf.pos)[both]))))
            err_b.append(np.nanmedian(np.abs(np.where(valid, pos, np.nan) - gt)))
            err_f.append(np.nanmedian(np.abs(jnp.where(cf.valid, cf.pos, np.nan) - gt)))
    b.extra["archive"] = dict(
        frames=len(batches[0]),
        worst_band_minus_full_px=max(diffs),
        median_err_band_px=float(np.median(err_b)),
        median_err_full_px=float(np.median(err_f)),
    )
    print(f"archive: {b.extra['archive']}", flush=True)


def bench_med_stages(b: Bench) -> None:
    """MED per stripe (cold, warm, precompute, one iteration), Steger, the NumPy MED peer."""
    import jax
    import jax.numpy as jnp

    from cslx.segmentation import med, med_fft, steger

    monos, F, n, slow, budget = b.monos, b.F, b.n, b.slow, b.budget
    for stripe, axis in (("h", 0), ("v", 1)):
        L = med.default_filter_length(b.frames.shape[1 + axis])
        cold_res = [med.med(I, axis=axis) for I in monos]
        steps = [int(c.steps) for c in cold_res]
        b.stage[f"med_{stripe}"] = b.add(
            "stage",
            f"MED {stripe} stripe, cold (flat, L={L})",
            timeit(
                lambda i, axis=axis: _block(med.med(monos[i], axis=axis)),
                list(range(F)),
                max(slow, n // 4),
                budget,
            ),
            med_steps=float(np.median(steps)),
        )
        warm_steps = []

        def warm(i, axis=axis, cold_res=cold_res, warm_steps=warm_steps):
            res = med.med(monos[i], axis=axis, init=cold_res[i - 1].filter)
            _block(res)
            warm_steps.append(int(res.steps))

        b.add(
            "stage",
            f"MED {stripe} stripe, warm (previous frame's filter)",
            timeit(warm, list(range(1, F)), max(slow, n // 4), budget),
            med_steps=float(np.median(warm_steps)),
        )
        outputs = [c.output for c in cold_res]
        b.stage[f"steger_{stripe}"] = b.add(
            "stage",
            f"Steger {stripe} stripe (σ={SIGMA}, one centre per {('column', 'row')[axis]})",
            timeit(
                lambda i, axis=axis, outputs=outputs: _block(
                    steger.steger_centres(outputs[i], sigma=SIGMA, axis=axis)
                ),
                list(range(F)),
                n,
                budget,
            ),
        )
        pb = [med.med_prepare(I, axis=axis, L=L) for I in monos[:4]]
        prep = jax.jit(lambda I, axis=axis, L=L: med.med_prepare(I, axis=axis, L=L))
        b.stage[f"prep_{stripe}"] = b.add(
            "stage",
            f"MED {stripe}: per-frame precompute (taper, FFTs)",
            timeit(lambda i, prep=prep: _block(prep(monos[i])), list(range(F)), n, budget),
        )
        upd = jax.jit(lambda W, p: med.med_update(W, p, 1e-5))
        W0 = cold_res[0].filter
        b.stage[f"iter_{stripe}"] = b.add(
            "stage",
            f"MED {stripe}: one fixed-point iteration (jit)",
            timeit(
                lambda i, upd=upd, W0=W0, pb=pb: _block(upd(W0, pb[i % 4])),
                list(range(4)),
                n,
                budget,
            ),
        )
        b.stage[f"cold_steps_{stripe}"] = float(np.median(steps))
        # The NumPy/SciPy peer on exactly the same input and filter.
        Xs = [
            np.asarray(
                med_fft.centre_and_taper(med.stripe_segments(monos[i], axis), med.DEFAULT_TAPER),
                np.float64,
            )
            for i in range(min(F, 4))
        ]
        Wflat = np.full(L, 1 / math.sqrt(L))
        ours_once = np.asarray(upd(jnp.asarray(Wflat, jnp.float32), pb[0])[0], np.float64)
        theirs_once = numpy_med_update(Wflat, numpy_med_prepare(Xs[0], L), 1e-5)
        b.extra[f"numpy_med_agreement_{stripe}"] = float(np.max(np.abs(ours_once - theirs_once)))
        t_prep = timeit(
            lambda i, Xs=Xs, L=L: numpy_med_prepare(Xs[i % len(Xs)], L),
            list(range(4)),
            slow,
            budget,
        )
        npbs = [numpy_med_prepare(x, L) for x in Xs]
        t_iter = timeit(
            lambda i, npbs=npbs, W=np.asarray(W0, np.float64): numpy_med_update(
                W, npbs[i % len(npbs)], 1e-5
            ),
            list(range(4)),
            slow * 2,
            budget,
        )
        b.add(
            "peer",
            f"NumPy/SciPy MED {stripe}: one iteration (solve_toeplitz)",
            t_iter,
            vs="MED iteration",
            ratio=t_iter["time_ms"] / b.stage[f"iter_{stripe}"]["time_ms"],
            max_filter_diff=b.extra[f"numpy_med_agreement_{stripe}"],
        )
        est = t_prep["time_ms"] + b.stage[f"cold_steps_{stripe}"] * t_iter["time_ms"]
        b.add(
            "peer",
            f"NumPy/SciPy MED {stripe}: precompute + {b.stage[f'cold_steps_{stripe}']:.0f} steps",
            dict(time_ms=est, p90_ms=math.nan, calls=t_iter["calls"]),
            vs=f"MED {stripe} cold",
            ratio=est / b.stage[f"med_{stripe}"]["time_ms"],
        )


def bench_tracking_pieces(b: Bench) -> None:
    """The pieces of the tracking path, each timed alone."""
    import jax
    import jax.numpy as jnp

    from cslx.runtime import pipeline, weld
    from cslx.segmentation import med, steger

    frames, monos, F, n, budget = b.frames, b.monos, b.F, b.n, b.budget
    config = pipeline.PipelineConfig()
    w = jnp.asarray(WEIGHTS, jnp.float32)
    matmul = jax.jit(lambda rgb: rgb.astype(jnp.float32) @ w)
    wsum = jax.jit(lambda rgb: pipeline.colour_sum(rgb, WEIGHTS, jnp.float32))
    assert np.allclose(np.asarray(wsum(frames[0])), np.asarray(matmul(frames[0])))
    b.stage["colour_matmul"] = b.add(
        "stage",
        "colour space as `x @ w` (uint8 RGB → R−G float32; before)",
        timeit(lambda i: _block(matmul(frames[i])), list(range(F)), n, budget),
    )
    b.stage["colour"] = b.add(
        "stage",
        "colour space as a channel-weighted sum (`pipeline.colour_sum`)",
        timeit(lambda i: _block(wsum(frames[i])), list(range(F)), n, budget),
    )
    hh, hw = 2 * config.roi_half_h, 2 * config.roi_half_w
    full = [
        pipeline.process_frame(
            b.sensor, config, f, pipeline.init_state(config, b.sensor.camera.image_size), roi=False
        )[0]
        for f in frames[:1]
    ]
    row0 = int(
        np.clip(np.nanmedian(np.asarray(full[0].centres_h.pos)) - hh // 2, 0, frames.shape[1] - hh)
    )
    col0 = int(
        np.clip(np.nanmedian(np.asarray(full[0].centres_v.pos)) - hw // 2, 0, frames.shape[2] - hw)
    )
    bands = {
        "h": ([I[row0 : row0 + hh] for I in monos], 0, f"{hh}×{frames.shape[2]}"),
        "v": ([I[:, col0 : col0 + hw] for I in monos], 1, f"{frames.shape[1]}×{hw}"),
    }
    for stripe, (band, axis, size) in bands.items():
        W = med.med(band[0], axis=axis, L=config.L_roi, symmetric=True, max_steps=60).filter
        # jitted as a whole like the other pieces: `med` outside a jit adds its Python
        # dispatch (argument checks, equinox's filter_jit) to every call
        warm = jax.jit(
            lambda x, W, axis=axis: med.med(
                x,
                axis=axis,
                L=config.L_roi,
                init=W,
                max_steps=config.roi_max_steps,
                symmetric=True,
                lag=config.roi_med_lag,
            )
        )
        steps = "one lagged step" if config.roi_med_lag else f"≤ {config.roi_max_steps} steps"
        b.stage[f"band_med_{stripe}"] = b.add(
            "stage",
            f"tracking: MED on the {stripe} band ({size}, L={config.L_roi}, linear phase, "
            f"warm, {steps})",
            timeit(
                lambda i, band=band, W=W, warm=warm: _block(warm(band[i], W)),
                list(range(F)),
                n,
                budget,
            ),
        )
        b.stage[f"band_{stripe}"] = b.add(
            "stage",
            f"tracking: Steger on the {stripe} band ({size})",
            timeit(
                lambda i, band=band, axis=axis: _block(
                    steger.steger_centres(band[i], sigma=SIGMA, axis=axis)
                ),
                list(range(F)),
                n,
                budget,
            ),
        )
    from cslx.runtime import band_input

    for stripe, axis, start, size in (("h", 0, row0, hh), ("v", 1, col0, hw)):
        cut = jax.jit(
            lambda rgb, axis=axis, start=start, size=size: band_input.band_image(
                rgb, start, size, axis, WEIGHTS, jnp.float32
            )
        )
        b.stage[f"band_in_{stripe}"] = b.add(
            "stage",
            f"tracking: {stripe} band cut from the RGB frame (colour sum, clipped-core fill)",
            timeit(lambda i, cut=cut: _block(cut(frames[i])), list(range(F)), n, budget),
        )
    whole = jax.jit(lambda rgb: band_input.frame_input(rgb, WEIGHTS, jnp.float32))
    b.stage["whole_input"] = b.add(
        "stage",
        "whole frame: colour sum + clipped-core fill along both axes (before)",
        timeit(lambda i: _block(whole(frames[i])), list(range(F)), n, budget),
    )
    for key, stride, label in (("stats_full", 1, "full frame, before"), ("stats", 4, "1/16")):
        fs = jax.jit(lambda rgb, stride=stride: band_input.frame_stats(rgb, jnp.float32, stride))
        b.stage[key] = b.add(
            "stage",
            f"tracking: frame brightness + saturation ({label})",
            timeit(lambda i, fs=fs: _block(fs(frames[i])), list(range(F)), n, budget),
        )
    sensor = b.sensor
    tri = jax.jit(
        lambda ch, cv: (
            pipeline.stripe_points(sensor, ch, 0, 0, jnp.float32),
            pipeline.stripe_points(sensor, cv, 1, 1, jnp.float32),
        )
    )
    state0 = pipeline.init_state(config, sensor.camera.image_size)
    results = [pipeline.process_frame(sensor, config, f, state0, roi=False)[0] for f in frames[:4]]
    b.stage["triangulation"] = b.add(
        "stage",
        "triangulation (both stripes, undistort + plane)",
        timeit(
            lambda i: _block(tri(results[i].centres_h, results[i].centres_v)),
            list(range(4)),
            n,
            budget,
        ),
    )

    def features(r):
        Ph, kh = pipeline.clean_profile(r.points_h, jnp.isfinite(r.points_h[:, 0]), config)
        Pv, kv = pipeline.clean_profile(r.points_v, jnp.isfinite(r.points_v[:, 0]), config)
        return weld.weld_features(Ph, kh, Pv, kv, config.weld)

    feat = jax.jit(features)
    b.stage["weld"] = b.add(
        "stage",
        "weld features (profile clean-up + bead fit, both stripes)",
        timeit(lambda i: _block(feat(results[i])), list(range(4)), n, budget),
    )


def bench_baselines(b: Bench) -> None:
    """Our NumPy baselines CM / LA / QA / AA on the horizontal stripe (R−G)."""
    from cslx.segmentation import baselines

    monos_np = [np.asarray(m) for m in b.monos]
    for name in ("cm", "la", "qa", "aa"):
        fn = getattr(baselines, name)
        b.add(
            "baseline",
            f"{name.upper()} (cslx.segmentation.baselines, h stripe)",
            timeit(
                lambda i, fn=fn: fn(monos_np[i], 0),
                list(range(b.F)),
                b.slow if name != "cm" else b.n,
                b.budget,
            ),
        )


def bench_filter_peers(b: Bench, skip_ridge: bool) -> None:
    """OpenCV + NumPy Steger, scikit-image Hessian eigenvalues, ridge-detection."""
    import cv2
    import jax.numpy as jnp

    from cslx.segmentation import med, steger

    slow, budget = b.slow, b.budget
    ours = b.stage["steger_h"]["time_ms"]
    outputs_np = [np.asarray(med.med(m, axis=0).output, np.float32) for m in b.monos[:4]]
    kernels = gaussian_kernels(SIGMA)
    t_cv = timeit(
        lambda i: opencv_steger(outputs_np[i % 4], kernels), list(range(4)), slow * 4, budget
    )
    pos_cv, valid_cv = opencv_steger(outputs_np[0], kernels)
    c_ours = steger.steger_centres(jnp.asarray(outputs_np[0]), sigma=SIGMA, axis=0)
    both = valid_cv & np.asarray(c_ours.valid)
    agree = (
        float(np.median(np.abs(pos_cv[both] - np.asarray(c_ours.pos)[both])))
        if both.any()
        else math.nan
    )
    b.add(
        "peer",
        "OpenCV sepFilter2D + NumPy Steger (h stripe)",
        t_cv,
        vs="Steger h",
        ratio=t_cv["time_ms"] / ours,
        median_pos_diff_px=agree,
        same_columns=float(np.mean(valid_cv == np.asarray(c_ours.valid))),
    )
    t_sk = timeit(lambda i: skimage_hessian(outputs_np[i % 4]), list(range(4)), slow * 4, budget)
    b.add(
        "peer",
        "scikit-image hessian_matrix + hessian_matrix_eigvals",
        t_sk,
        vs="Steger h",
        ratio=t_sk["time_ms"] / ours,
    )
    b.extra["cv2_cvtColor_ms"] = timeit(
        lambda i: cv2.cvtColor(b.frames[i], cv2.COLOR_RGB2GRAY), list(range(b.F)), b.n, budget
    )["time_ms"]
    if skip_ridge:
        b.extra["ridge_detection"] = "skipped (--skip-ridge)"
        return
    try:
        import ridge_detection  # noqa: F401
    except ImportError as err:
        b.extra["ridge_detection"] = f"not installed ({err}); pip install 'cslx[bench]'"
        return
    mono_u8 = [np.clip(np.asarray(m), 0, 255).astype(np.uint8) for m in b.monos]
    times, n_lines = [], []
    for i in range(b.cfg["ridge_frames"]):
        t = time.perf_counter()
        lines = ridge_detection_peer(mono_u8[i])
        times.append(time.perf_counter() - t)
        n_lines.append(len(lines))
    ms = 1e3 * np.asarray(times)
    b.add(
        "peer",
        "ridge-detection (PyPI, Steger's detector in Python)",
        dict(time_ms=float(np.median(ms)), p90_ms=float(np.max(ms)), calls=len(ms)),
        vs="Steger h",
        ratio=float(np.median(ms)) / ours,
        lines_found=int(np.median(n_lines)),
    )


def bench_batch(b: Bench) -> None:
    """`process_batch` (full frame, cold start state) on 1, 4, 16 consecutive video frames.

    Three ways: the CPU default (frame by frame, each frame's MED warm-started from the
    filters the previous frame converged to, `lax.scan`), frame by frame from the same cold
    start (``warm=False``, `lax.map`), and vmap (the old default). The warm batch's centres
    are compared with the cold one's (both-valid centres, |Δ| median and 99th percentile).
    """
    import jax.numpy as jnp

    from cslx.runtime import pipeline
    from cslx.runtime.batch import process_batch

    config = pipeline.PipelineConfig()
    modes = (
        ("frame by frame, MED warm-started from the previous frame (lax.scan, CPU default)",
         "auto", True),
        ("frame by frame, each from the cold start (lax.map, warm=False)", "auto", False),
        ("vmap", None, False),
    )  # fmt: skip
    last = {}
    for mode, vmap_size, warm in modes:
        for B in (1, 4, 16):
            batch = jnp.asarray(b.frames[np.arange(B) % b.F])

            def run(_, batch=batch, vmap_size=vmap_size, warm=warm):
                out = process_batch(b.sensor, config, batch, vmap_size=vmap_size, warm=warm)
                return _block(out)

            res = timeit(run, [0], 3, b.budget, warmup=1)
            b.add(
                "batch",
                f"process_batch, full frame, batch {B} ({mode})",
                res,
                frames_per_s=B / (res["time_ms"] / 1e3),
                ms_per_frame=res["time_ms"] / B,
                compile_s=res["first_ms"] / 1e3 - res["time_ms"] / 1e3,
            )
            if B == 16 and vmap_size == "auto":
                last[warm] = run(0)[0]
    if len(last) == 2:
        d = []
        for name in ("centres_h", "centres_v"):
            cw, cc = getattr(last[True], name), getattr(last[False], name)
            both = np.asarray(cw.valid & cc.valid)
            d.append(np.abs(np.asarray(cw.pos) - np.asarray(cc.pos))[both])
        d = np.concatenate(d)
        b.extra["batch_warm_vs_cold_median_px"] = float(np.median(d))
        b.extra["batch_warm_vs_cold_p99_px"] = float(np.percentile(d, 99))


def bench_cli_extract(b: Bench) -> None:
    """`cslx extract --method med` end to end (a subprocess) on PNG archives.

    Runs of CLI_BASE_FRAMES and of ``cli_frames`` files, three times each, interleaved, after one
    untimed run that fills a persistent compile cache (``CSLX_JAX_CACHE``, a temporary
    folder) so that every timed run loads its program instead of compiling it (a compile of
    ≈ 20 s varies by seconds under load, which made the difference of two compiling runs
    swing by tens of ms per frame). Per frame: the median over the three pairs of the time
    difference over the frame difference (start-up, imports and cache loading cancel). The
    long run has 240 files: with 48 the difference (≈ 0.35 s) was below the run-to-run
    scatter of the process start (a run at 17b9d8a gave −0.8 ms per frame); a difference
    that is not positive is reported as not measured.
    """
    import cv2

    n_big = max(b.cfg["cli_frames"], CLI_BASE_FRAMES + 1)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    with tempfile.TemporaryDirectory() as tmp:
        env["CSLX_JAX_CACHE"] = os.path.join(tmp, "jax-cache")
        paths = []
        for i in range(n_big):
            p = os.path.join(tmp, f"f{i:04d}.png")
            cv2.imwrite(p, cv2.cvtColor(b.frames[i % b.F], cv2.COLOR_RGB2BGR))
            paths.append(p)
        walls: dict[int, list[float]] = {CLI_BASE_FRAMES: [], n_big: []}
        for k, count in enumerate((CLI_BASE_FRAMES,) + (CLI_BASE_FRAMES, n_big) * 3):
            out = os.path.join(tmp, f"c{count}.csv")
            cmd = [sys.executable, "-m", "cslx", "extract", "--method", "med", "--space", "r-g"]
            cmd += ["--stripe", "both", "--out", out, *paths[:count]]
            t = time.perf_counter()
            proc = subprocess.run(cmd, capture_output=True, text=True, env=env, timeout=3600)
            if k > 0:  # the first run fills the compile cache
                walls[count].append(time.perf_counter() - t)
            if proc.returncode != 0:
                raise RuntimeError(f"cslx extract failed:\n{proc.stderr[-3000:]}")
        with open(os.path.join(tmp, f"c{n_big}.csv")) as f:
            rows = sum(1 for _ in f) - 1
    pairs = zip(walls[n_big], walls[CLI_BASE_FRAMES], strict=True)
    per_frame = float(np.median([1e3 * (a - b) / (n_big - CLI_BASE_FRAMES) for a, b in pairs]))
    wall = {c: float(np.median(w)) for c, w in walls.items()}
    b.stage["cli"] = b.add(
        "cli",
        f"cslx extract --method med --stripe both, per frame ({n_big} − {CLI_BASE_FRAMES} PNGs)",
        dict(time_ms=per_frame, p90_ms=math.nan, calls=1),
        frames_per_s=1e3 / per_frame if per_frame > 0 else math.nan,
    )
    b.extra["cli"] = dict(
        frames=n_big,
        wall_s=wall[n_big],
        base_frames=CLI_BASE_FRAMES,
        base_wall_s=wall[CLI_BASE_FRAMES],
        centre_rows=rows,
    )


def bench_compile_cache(b: Bench) -> None:
    """The tracker's start-up in fresh processes sharing a persistent compile cache: one that
    compiles, then CACHED_STARTS that load the program (median; the machine is shared)."""
    with tempfile.TemporaryDirectory() as cache:
        first = _start_subprocess(cache)
        cached = [_start_subprocess(cache) for _ in range(CACHED_STARTS)]
    b.extra["tracker_compile_first_s"] = first["compile_s"]
    b.extra["tracker_compile_cached_s"] = float(np.median([r["compile_s"] for r in cached]))
    b.extra["tracker_start_first_s"] = first["start_to_first_frame_s"]
    starts = [r["start_to_first_frame_s"] for r in cached]
    b.extra["tracker_start_cached_s"] = float(np.median(starts))
    b.extra["tracker_start_cached_all_s"] = starts
    b.extra["tracker_start_cached_cpu_s"] = float(np.median([r["cpu_s"] for r in cached]))


def bench_memory(b: Bench) -> None:
    """A long tracker run in a fresh process: RSS, Python heap, peak memory."""
    b.extra["memory"] = _subprocess(
        "--worker-memory", str(b.cfg["long_frames"]), str(b.seed), str(b.cfg["video_frames"])
    )
    b.extra["bench_process_peak_rss_mb"] = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024


# --------------------------------------------------------------------- sub-processes
def _worker_compile(cache_dir: str, t_spawn: float) -> dict:
    """One fresh process: build the tracker with a persistent compilation cache, step a frame.

    Timed from ``t_spawn``, the parent's `time.monotonic` (a system-wide clock) just before it
    started this process, so the interpreter's start and this script's imports count. The
    garbage collector is off until the tracker is built, as in `cslx track` (its ``_run``).
    """
    gc.disable()
    import jax

    jax.config.update("jax_compilation_cache_dir", cache_dir)
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    from cslx.runtime.tracker import Tracker

    tracker = Tracker.from_calibration(sensor32(), log=lambda s: None)
    gc.enable()
    frame = np.zeros(tracker.image_shape, np.uint8)
    tracker.step(frame)
    return dict(
        compile_s=tracker.compile_s,
        start_to_first_frame_s=time.monotonic() - t_spawn,
        cpu_s=time.process_time(),
    )


def _worker_memory(n_frames: int, seed: int, n_video: int) -> dict:
    """A tracker process stepping n_frames: RSS samples, tracemalloc, peak RSS."""
    import tracemalloc

    from cslx.runtime.tracker import Tracker

    def rss_mb():
        with open("/proc/self/statm") as f:
            return int(f.read().split()[1]) * os.sysconf("SC_PAGE_SIZE") / 2**20

    frames = video_frames(n_video, seed)
    tracker = Tracker.from_calibration(sensor32(), log=lambda s: None)
    order = ping_pong(len(frames), n_frames)
    for i in range(50):  # warm-up
        tracker.step(frames[order[i]])
    tracemalloc.start()
    base = tracemalloc.take_snapshot()
    samples, latencies = [], np.zeros(n_frames)
    every = max(1, n_frames // 20)
    t0 = time.perf_counter()
    for i in range(n_frames):
        if i % every == 0:
            samples.append((i, rss_mb(), tracemalloc.get_traced_memory()[0] / 2**20))
        latencies[i] = tracker.step(frames[order[i]]).latency_ms
    wall = time.perf_counter() - t0
    samples.append((n_frames, rss_mb(), tracemalloc.get_traced_memory()[0] / 2**20))
    top = tracemalloc.take_snapshot().compare_to(base, "lineno")[:3]
    tracemalloc.stop()
    i, rss, py = np.asarray(samples).T
    half = len(i) // 2
    # Growth over the second half of the run (after caches and allocator pools settle).
    slope_rss = float(np.polyfit(i[half:], rss[half:], 1)[0] * 1000)
    return dict(
        frames=n_frames,
        wall_s=wall,
        step_median_ms=float(np.median(latencies)),
        peak_rss_mb=resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024,
        rss_start_mb=float(rss[0]),
        rss_end_mb=float(rss[-1]),
        rss_growth_mb_per_1000_frames=slope_rss,
        python_heap_start_mb=float(py[0]),
        python_heap_end_mb=float(py[-1]),
        python_heap_growth_kb_per_1000_frames=float(
            np.polyfit(i[half:], py[half:], 1)[0] * 1000 * 1024
        ),
        top_growth=[str(s) for s in top],
    )


def _start_subprocess(cache: str) -> dict:
    """`_worker_compile` in a fresh process, timed from just before the process starts."""
    return _subprocess("--worker-compile", cache, repr(time.monotonic()))


def _subprocess(*args: str, timeout: float = 1800) -> dict:
    env = dict(os.environ)
    env["PYTHONPATH"] = str(ROOT) + os.pathsep + env.get("PYTHONPATH", "")
    env.pop("JAX_COMPILATION_CACHE_DIR", None)
    # As a module, so that the `experiments` package (`cslx.environment.configure`) loads
    # before this script's NumPy: run as a file, the package came after NumPy and its BLAS
    # limit then imported SciPy (≈ 0.1 s CPU of the start-up worker that no robot pays).
    proc = subprocess.run(
        [sys.executable, "-m", "experiments.bench_speed", *args],
        capture_output=True,
        text=True,
        env=env,
        timeout=timeout,
        cwd=ROOT,
    )
    if proc.returncode != 0:
        raise RuntimeError(f"bench worker {args} failed:\n{proc.stderr[-3000:]}")
    return json.loads(proc.stdout.strip().splitlines()[-1])


# ------------------------------------------------------------------------------- main
def main(
    quick: bool = False,
    seed: int = 0,
    out: str | os.PathLike = RESULTS,
    skip_ridge: bool = False,
    only: tuple[str, ...] | None = None,
    **overrides,
) -> list[dict]:
    """Run the benchmark; returns the table rows (also written to results/bench_speed.*)."""
    cfg = dict(QUICK if quick else FULL)
    cfg.update({k: v for k, v in overrides.items() if v is not None})
    load_start = load_average()
    t_run = time.perf_counter()
    import jax
    import jax.numpy as jnp

    from cslx.provenance import provenance, write_csv
    from cslx.runtime.pipeline import colour_sum

    frames, truth = video_frames(cfg["video_frames"], seed, with_truth=True)
    colour = jax.jit(lambda rgb: colour_sum(rgb, WEIGHTS, jnp.float32))
    monos = [colour(jnp.asarray(f)) for f in frames]
    b = Bench(cfg, seed, sensor32(), frames, truth, monos)
    steps = [
        ("pipeline", bench_pipeline),
        ("agreement", bench_band_agreement),
        ("med", bench_med_stages),
        ("pieces", bench_tracking_pieces),
        ("baselines", bench_baselines),
        ("peers", lambda b: bench_filter_peers(b, skip_ridge)),
        ("batch", bench_batch),
        ("archive", bench_archive),
        ("cli", bench_cli_extract),
        ("compile", bench_compile_cache),
        ("memory", bench_memory),
    ]
    for name, fn in steps:
        if only is None or name in only:
            fn(b)
    b.extra["machine"] = machine_record(load_start)
    b.extra["wall_s"] = time.perf_counter() - t_run
    prov = provenance(
        dict(
            cfg,
            quick=quick,
            seed=seed,
            frames="render_video(sunny), 640×480",
            only=list(only) if only else "all",
            **b.extra["machine"],
        )
    )
    os.makedirs(out, exist_ok=True)
    fields = [
        "group", "name", "time_ms", "p90_ms", "calls", "vs", "ratio", "med_steps",
        "roi_fraction", "frames_per_s", "ms_per_frame", "compile_s", "max_filter_diff",
        "median_pos_diff_px", "same_columns", "lines_found", "gated",
    ]  # fmt: skip
    write_csv(os.path.join(out, "bench_speed.csv"), b.rows, fields)
    with open(os.path.join(out, "bench_speed.md"), "w", encoding="utf-8") as f:
        f.write(_markdown(b, prov, quick))
    return b.rows


def _verdict(ok) -> str:
    if ok is None:
        return "not measured"
    return "**met**" if ok else "**not met**"


def _targets(b: Bench) -> list[dict]:
    """The goals of issue 13 (and the Steger goals of issue 7) against this run's numbers."""
    st, ex = b.stage, b.extra
    rows = []

    def get(key):
        return st.get(key, {}).get("time_ms")

    tr = st.get("tracking")
    agr = ex.get("agreement_symmetric")
    if tr is not None:
        unbiased = "" if agr is None else f"; band − full {agr['worst_tracking_px']:.3f} px"
        rows.append(
            dict(
                target="tracking mode ≤ 2.5 ms median, MED in the bands",
                measured=f"{tr['time_ms']:.2f} ms (p90 {tr['p90_ms']:.2f}; ROI on "
                f"{100 * tr['roi_fraction']:.0f} % of frames; MED steps {tr['med_steps']})"
                + unbiased
                + (
                    f"; the robot's `Tracker.step` with MED in the bands "
                    f"{st['tracker_med']['time_ms']:.2f} ms"
                    if "tracker_med" in st
                    else ""
                ),
                verdict=_verdict(tr["time_ms"] <= 2.5),
            )
        )
    if agr is not None:
        rows.append(
            dict(
                target="band centres = full-frame MED centres within 0.05 px (median, worst "
                "frame and stripe)",
                measured=f"tracking {agr['worst_tracking_px']:.3f} px, first-pass bands "
                f"{agr['worst_first_pass_px']:.3f} px over {agr['frames']} frames × 2 stripes",
                verdict=_verdict(max(agr["worst_tracking_px"], agr["worst_first_pass_px"]) <= 0.05),
            )
        )
    for key, label in (
        ("cold_bands", "cold frame ≤ 25 ms (MED on both stripes + detection; first-pass bands)"),
        ("cold_full", "cold full frame ≤ 25 ms (MED on the whole frame, both stripes)"),
    ):
        r = st.get(key)
        if r is not None:
            rows.append(
                dict(
                    target=label,
                    measured=f"{r['time_ms']:.1f} ms, MED steps {r['med_steps']}, bands on "
                    f"{100 * r['roi_fraction']:.0f} % of frames",
                    verdict=_verdict(r["time_ms"] <= 25.0),
                )
            )
    if get("cli") is not None:
        rows.append(
            dict(
                target="`cslx extract --method med` ≤ 20 ms per frame (decode + CSV included)",
                measured=f"{get('cli'):.1f} ms per frame (both stripes)",
                verdict=_verdict(get("cli") <= 20.0 if get("cli") > 0 else None),
            )
        )
    batch = [r for r in b.rows if r["group"] == "batch" and "CPU default" in r["name"]]
    if batch:
        per = [r["ms_per_frame"] for r in batch]
        rows.append(
            dict(
                target="per-frame batch cost flat or falling (1 → 4 → 16 frames)",
                measured=" → ".join(f"{p:.1f}" for p in per)
                + " ms per frame (consecutive frames, MED warm-started from the previous one"
                + (
                    f"; centres vs cold start |Δ| median {ex['batch_warm_vs_cold_median_px']:.3f}"
                    f", p99 {ex['batch_warm_vs_cold_p99_px']:.3f} px)"
                    if "batch_warm_vs_cold_median_px" in ex
                    else ")"
                ),
                verdict=_verdict(per[-1] <= 1.1 * per[0]),
            )
        )
    if "tracker_compile_cached_s" in ex:
        rows.append(
            dict(
                target="start-up with a warm compile cache ≤ 1.5 s (process start → first frame)",
                measured=f"compile {ex['tracker_compile_cached_s']:.1f} s; process start → "
                f"first frame {ex['tracker_start_cached_s']:.2f} s (median of "
                f"{len(ex['tracker_start_cached_all_s'])} fresh processes, CPU "
                f"{ex['tracker_start_cached_cpu_s']:.2f} s)",
                verdict=_verdict(ex["tracker_start_cached_s"] <= 1.5),
            )
        )
    cv = next((r for r in b.rows if r["name"].startswith("OpenCV")), None)
    sk = next((r for r in b.rows if r["name"].startswith("scikit-image")), None)
    rd = next((r for r in b.rows if r["name"].startswith("ridge-detection")), None)
    steger_h = get("steger_h")
    for peer, label, bound in (
        (cv, "Steger stage faster than OpenCV filters + NumPy Steger", 1),
        (sk, "Steger stage faster than scikit-image Hessian eigenvalues", 1),
        (rd, "≥ 1000× faster than ridge-detection", 1000),
    ):
        if peer is not None and steger_h is not None:
            rows.append(
                dict(
                    target=label,
                    measured=f"{steger_h:.2f} ms vs {peer['time_ms']:.2f} ms "
                    f"(×{peer['ratio']:.1f})",
                    verdict=_verdict(peer["ratio"] >= bound),
                )
            )
    return rows


def _markdown(b: Bench, prov, quick) -> str:
    from cslx.provenance import md_table, provenance_md

    st, ex = b.stage, b.extra
    m = ex["machine"]
    out = [
        "# Speed: cslx and its peers on the same 640×480 frames, one run\n\n",
        "Produced by `experiments/bench_speed.py`"
        + (" **--quick** (fewer calls; smoke run)" if quick else "")
        + ". Median wall time per call after warm-up; every JAX result blocked "
        "(`jax.block_until_ready`). Frames: consecutive rendered video frames (`sunny`, seed "
        f"{b.seed}), float32 path.\n\n",
        f"**Machine load**: the machine is shared; load average (1/5/15 min) at the start "
        f"{m['load_start']}, at the end {m['load_end']} on {m['cores']} cores. Absolute "
        "times are inflated accordingly; the before/after and peer/cslx ratios were taken in "
        "the same run.\n\n",
        "## Goals (issue 13; Steger goals of issue 7)\n\n",
        md_table(_targets(b), ["target", "measured", "verdict"]),
    ]
    notes = []
    if "tracking" in st and "tracking_no_med" in st:
        pieces = {
            k: st[k]["time_ms"]
            for k in (
                "band_in_h",
                "band_in_v",
                "band_med_h",
                "band_med_v",
                "band_h",
                "band_v",
                "weld",
                "stats",
                "triangulation",
            )
            if k in st
        }
        listed = ", ".join(f"{k} {v:.2f} ms" for k, v in pieces.items())
        notes.append(
            f"- Tracking mode: {st['tracking']['time_ms']:.2f} ms with MED in the bands, "
            f"{st['tracking_no_med']['time_ms']:.2f} ms without it"
            + (
                f", {st['tracking_whole_frame']['time_ms']:.2f} ms converting the whole frame "
                "first (before)"
                if "tracking_whole_frame" in st
                else ""
            )
            + ". Pieces timed "
            f"alone: {listed} (sum {sum(pieces.values()):.2f} ms; the rest is dispatch, "
            "band bookkeeping and the lax.cond).\n"
        )
    for key, label, _ in BAND_VARIANTS:
        a = ex.get(f"agreement_{key}")
        if a:
            notes.append(
                f"- {label}: band − full-frame MED centres, worst |median| over "
                f"{a['frames']} frames × 2 stripes: tracking {a['worst_tracking_px']:.3f} px, "
                f"first-pass bands {a['worst_first_pass_px']:.3f} px; median |centre − truth| "
                f"full frame {a['median_err_full_px']:.3f} px, tracking "
                f"{a['median_err_tracking_px']:.3f} px, first pass "
                f"{a['median_err_first_pass_px']:.3f} px.\n"
            )
    if "archive" in ex:
        a = ex["archive"]
        notes.append(
            f"- Archives (`med_bands.extract_frames`, what `cslx extract --method med` runs): "
            f"{st['archive']['time_ms']:.2f} ms per frame, MED steps {st['archive']['med_steps']}"
            f", bands on {100 * st['archive']['roi_fraction']:.0f} % of frames; from the flat "
            f"start on {a['frames']} frames, band − full-frame MED worst |median| "
            f"{a['worst_band_minus_full_px']:.3f} px, median |centre − truth| band "
            f"{a['median_err_band_px']:.3f} px, full frame {a['median_err_full_px']:.3f} px.\n"
        )
    if "colour" in st and "colour_matmul" in st:
        notes.append(
            f"- Colour space: `x @ w` {st['colour_matmul']['time_ms']:.3f} ms → channel-weighted "
            f"sum {st['colour']['time_ms']:.3f} ms.\n"
        )
    if "cli" in ex:
        c = ex["cli"]
        notes.append(
            f"- `cslx extract` (warm compile cache, medians of 3 runs): {c['frames']} PNGs in "
            f"{c['wall_s']:.1f} s, {c['base_frames']} in {c['base_wall_s']:.1f} s "
            f"({c['centre_rows']} centre rows written); the difference per frame is the "
            "goal's figure.\n"
        )
    if notes:
        out += ["\n## Reading\n\n", *notes]
    out += [
        "\n## Everything timed\n\n",
        md_table(
            b.rows,
            [
                "group",
                "name",
                "time_ms",
                "p90_ms",
                "calls",
                "vs",
                "ratio",
                "med_steps",
                "roi_fraction",
                "ms_per_frame",
                "gated",
            ],  # fmt: skip
            floatfmt=".3g",
        ),
    ]
    if "numpy_med_agreement_h" in ex:
        out.append(
            "\n`ratio` = peer time / cslx time of the stage named in `vs`. NumPy MED: one "
            f"update agrees with ours to {ex['numpy_med_agreement_h']:.1e} (h) / "
            f"{ex['numpy_med_agreement_v']:.1e} (v) max abs filter difference (float64 NumPy "
            "vs float32 JAX); its full-convergence time is precompute + the cold step count × "
            "one iteration.\n"
        )
    cv = next((r for r in b.rows if r["name"].startswith("OpenCV")), None)
    if cv is not None:
        out.append(
            f"OpenCV+NumPy Steger: median |Δ| to our centres {cv['median_pos_diff_px']:.2g} px, "
            f"same valid columns on {100 * cv['same_columns']:.1f} %. scikit-image computes the "
            "Hessian eigenvalues only (no offsets, no selection). A plain memory pass "
            f"(`cv2.cvtColor` RGB→gray) takes {ex['cv2_cvtColor_ms']:.2f} ms.\n"
        )
    if "ridge_detection" in ex:
        out.append(f"\nridge-detection: {ex['ridge_detection']}.\n")
    if "compile_tracking_s" in ex:
        out += [
            "\n## Compile time and the persistent cache\n\n",
            f"- first call of `process_frame` (trace + compile + run): tracking program "
            f"{ex['compile_tracking_s']:.1f} s, full-frame program "
            f"{ex['compile_full_frame_s']:.1f} s.\n",
        ]
    if "tracker_compile_first_s" in ex:
        out.append(
            "- `Tracker` start-up compile in a fresh process: "
            f"{ex['tracker_compile_first_s']:.1f} s with an empty persistent cache, "
            f"{ex['tracker_compile_cached_s']:.1f} s at the later starts with the same "
            "`jax_compilation_cache_dir` (process start → first frame "
            f"{ex['tracker_start_first_s']:.1f} s → {ex['tracker_start_cached_s']:.2f} s, "
            "median of "
            + ", ".join(f"{t:.2f}" for t in ex["tracker_start_cached_all_s"])
            + " s).\n"
        )
    mem = ex.get("memory")
    if mem:
        out += [
            "\n## Memory (a tracker process)\n\n",
            f"- {mem['frames']} frames stepped with `Tracker.step` (after 50 warm-up frames), "
            f"median step {mem['step_median_ms']:.2f} ms, {mem['wall_s']:.0f} s in all.\n",
            f"- peak resident memory (`ru_maxrss`, includes the XLA compile at start-up): "
            f"{mem['peak_rss_mb']:.0f} MB; steady RSS while stepping "
            f"{mem['rss_start_mb']:.0f} MB → {mem['rss_end_mb']:.0f} MB; growth over the "
            f"second half {mem['rss_growth_mb_per_1000_frames']:.2f} MB per 1000 frames.\n",
            f"- Python heap (tracemalloc): {mem['python_heap_start_mb']:.2f} MB → "
            f"{mem['python_heap_end_mb']:.2f} MB, second-half slope "
            f"{mem['python_heap_growth_kb_per_1000_frames']:.1f} kB per 1000 frames.\n",
        ]
    out += [
        "\n## Provenance\n\n",
        provenance_md(prov),
        f"- threads: OPENBLAS_NUM_THREADS={m['OPENBLAS_NUM_THREADS']} (OpenBLAS's threaded "
        f"Cholesky stalls MED here); XLA_FLAGS=`{m['XLA_FLAGS']}`; wall time of the run "
        f"{ex['wall_s'] / 60:.1f} min.\n",
    ]
    return "".join(out)


def _cli(argv=None):
    p = argparse.ArgumentParser(
        description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--quick", action="store_true", help="fewer calls and frames (smoke run)")
    p.add_argument("--seed", type=int, default=0)
    p.add_argument("--out", default=str(RESULTS))
    p.add_argument("--calls", type=int, help="timed calls of the fast functions")
    p.add_argument("--long-frames", type=int, help="frames of the memory run")
    p.add_argument("--ridge-frames", type=int, help="frames for ridge-detection (1–3)")
    p.add_argument("--cli-frames", type=int, help="PNG files of the long `cslx extract` run")
    p.add_argument("--skip-ridge", action="store_true", help="do not run ridge-detection")
    p.add_argument("--only", nargs="+", help="run only these measurements (names in main)")
    p.add_argument("--worker-compile", nargs=2, metavar="X", help=argparse.SUPPRESS)
    p.add_argument("--worker-memory", nargs=3, metavar="N", help=argparse.SUPPRESS)
    a = p.parse_args(argv)
    if a.worker_compile:
        cache, t_spawn = a.worker_compile
        print(json.dumps(_worker_compile(cache, float(t_spawn))))
        return
    if a.worker_memory:
        n_frames, seed, n_video = map(int, a.worker_memory)
        print(json.dumps(_worker_memory(n_frames, seed, n_video)))
        return
    main(
        quick=a.quick,
        seed=a.seed,
        out=a.out,
        skip_ridge=a.skip_ridge,
        only=tuple(a.only) if a.only else None,
        calls=a.calls,
        long_frames=a.long_frames,
        ridge_frames=a.ridge_frames,
        cli_frames=a.cli_frames,
    )


if __name__ == "__main__":
    _cli()
