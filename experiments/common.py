"""Helpers shared by the experiment scripts: seeded frames, per-point errors, drawing.

Every frame an experiment uses is rendered by `cslx.sim` from a seed that the script
states in its output; `frame_at` reproduces one frame from (kind, nuisance, seed, index)
without rendering the others.
"""

from __future__ import annotations

import argparse
import os
import pathlib
import time
from collections.abc import Callable, Iterator
from typing import Any

import numpy as np

ROOT = pathlib.Path(__file__).resolve().parents[1]
RESULTS = ROOT / "results"

#: Scene kinds of `cslx.sim.random_world`.
KINDS = ("straight", "cross")
#: The two colour spaces of Table 6 (eq. (8) weights).
SPACES = {"r": (1.0, 0.0, 0.0), "r-g": (1.0, -1.0, 0.0)}
SPACE_LABEL = {"r": "R", "r-g": "R−G", "gray": "gray", "auto": "kurtosis", "cont": "continuous"}
#: The paper's five methods of Table 6, in its order.
PAPER_METHODS = ("cm", "la", "qa", "aa", "med")
METHOD_LABEL = {
    "cm": "CM",
    "la": "LA",
    "qa": "QA",
    "aa": "AA",
    "med": "MED",
    "steger": "Steger (no MED)",
}
METHOD_COLOUR = {
    "cm": "tab:blue",
    "la": "tab:orange",
    "qa": "tab:green",
    "aa": "tab:purple",
    "steger": "tab:gray",
    "med": "tab:red",
}
STRIPE_PLANE = {"h": 0, "v": 1}
STRIPE_GT = {"h": "h_xyz", "v": "v_xyz"}


def conditions() -> list[tuple[str, str]]:
    """Every (scene kind, nuisance preset) pair, in a fixed order."""
    from cslx import sim as synth

    return [(k, n) for n in synth.NUISANCES for k in KINDS]


def frame_at(kind: str, nuisance, seed: int, index: int, sensor=None):
    """Frame `index` of the seeded data set (kind, nuisance, seed): (image, gt).

    Uses the generator `default_rng([seed, index])` for the world, pose and noise seed in
    the order `cslx.sim.render_dataset` draws them, so `frame_at(k, n, s, i)` equals
    `render_dataset(k, n, N, s)[i]` for any N > i.
    """
    from cslx import sim as synth
    from cslx.sensor import default_sensor

    sensor = sensor or default_sensor()
    rng = np.random.default_rng([seed, index])
    world = synth.random_world(kind, rng)
    pose = synth.random_pose(world, kind, rng, sensor)
    return synth.render_frame(sensor, world, pose, nuisance, seed=int(rng.integers(2**31)))


def condition_seed(seed: int, k: int) -> int:
    """Seed of the k-th condition's data set, derived from the run's seed."""
    return 1000 * int(seed) + int(k)


def round_robin(n_frames: int, seed: int, sensor=None) -> Iterator[tuple[str, str, int, Any, Any]]:
    """Frames cycling through `conditions()`: yields (kind, nuisance, seed, image, gt).

    Frame f belongs to condition f mod C and is frame f // C of that condition's data set
    (seed `condition_seed(seed, c)`), so stopping early keeps the conditions balanced.
    """
    conds = conditions()
    for f in range(n_frames):
        c = f % len(conds)
        kind, nuisance = conds[c]
        s = condition_seed(seed, c)
        image, gt = frame_at(kind, nuisance, s, f // len(conds), sensor)
        yield kind, nuisance, s, image, gt


def point_errors(uv: np.ndarray, gt_xyz: np.ndarray, sensor, plane: int):
    """Per-point 3-D and pixel errors of matched centres (`stripe_point_errors`)."""
    from cslx.segmentation import stripe_point_errors

    return stripe_point_errors(uv, gt_xyz, sensor, plane)


class Pool:
    """Accumulates per-point errors of one (stripe, space, method) over frames."""

    def __init__(self):
        self.err: list[np.ndarray] = []
        self.px: list[np.ndarray] = []
        self.n_gt = 0
        self.n_fp = 0
        self.frames = 0

    def add(self, err, px, n_gt, n_fp):
        self.err.append(err)
        self.px.append(px)
        self.n_gt += n_gt
        self.n_fp += n_fp
        self.frames += 1

    def summary(self, gross_mm: float = 1.0) -> dict[str, float]:
        """Pooled mean / median / p95 (mm), pixel error, detection rate, gross outliers."""
        err = np.concatenate(self.err) if self.err else np.zeros(0)
        px = np.concatenate(self.px) if self.px else np.zeros(0)
        nan = float("nan")
        n = len(err)
        return dict(
            frames=self.frames,
            mean_mm=float(np.mean(err)) if n else nan,
            median_mm=float(np.median(err)) if n else nan,
            p95_mm=float(np.percentile(err, 95)) if n else nan,
            mean_px=float(np.mean(px)) if n else nan,
            median_px=float(np.median(px)) if n else nan,
            detection_rate=n / self.n_gt if self.n_gt else nan,
            gross_rate=float(np.mean(err > gross_mm)) if n else nan,
            gross_outliers=int(np.sum(err > gross_mm)),
            false_positives=self.n_fp,
            n_gt=self.n_gt,
            n_matched=n,
        )


def timeit(
    fn: Callable[[Any], Any],
    inputs: list,
    n_calls: int,
    budget_s: float,
    warmup: int = 2,
    min_calls: int = 3,
) -> dict[str, float]:
    """Median / p90 wall time (ms) of `fn(x)` cycling over `inputs`, after warm-up.

    The first call (jit compile + run) is timed on its own (`first_ms`), then `warmup` more
    calls run untimed. Stops after `n_calls` timed calls or once `budget_s` seconds have been
    spent (at least `min_calls`). `fn` must block until its result is ready (e.g.
    `jax.block_until_ready` or a conversion to NumPy).
    """
    t0 = time.perf_counter()
    fn(inputs[0])
    first = time.perf_counter() - t0
    for i in range(warmup):
        fn(inputs[(i + 1) % len(inputs)])
    times = []
    start = time.perf_counter()
    while len(times) < n_calls and (
        len(times) < min(min_calls, n_calls) or time.perf_counter() - start < budget_s
    ):
        x = inputs[len(times) % len(inputs)]
        t = time.perf_counter()
        fn(x)
        times.append(time.perf_counter() - t)
    ms = np.asarray(times) * 1e3
    return dict(
        time_ms=float(np.median(ms)),
        p90_ms=float(np.percentile(ms, 90)),
        calls=len(ms),
        first_ms=first * 1e3,
    )


def time_calls(
    fn: Callable[[Any], Any], inputs: list, n_calls: int, budget_s: float, warmup: int = 3
) -> dict[str, float]:
    """`timeit` (at least 5 calls) with Table 6's column names: time_ms, time_p90_ms,
    time_calls, first_ms."""
    r = timeit(fn, inputs, n_calls, budget_s, warmup=warmup, min_calls=5)
    return dict(
        time_ms=r["time_ms"],
        time_p90_ms=r["p90_ms"],
        time_calls=r["calls"],
        first_ms=r["first_ms"],
    )


def load_average() -> str:
    """The 1/5/15-minute load averages (the machine is shared; timings depend on it)."""
    try:
        return " / ".join(f"{x:.1f}" for x in os.getloadavg())
    except OSError:
        return "unknown"


def machine_record(load_start: str | None = None) -> dict[str, Any]:
    """What a timing depends on besides the code: cores, load at start and now, threads."""
    return dict(
        cores=os.cpu_count(),
        load_start=load_start if load_start is not None else load_average(),
        load_end=load_average(),
        OPENBLAS_NUM_THREADS=os.environ.get("OPENBLAS_NUM_THREADS"),
        XLA_FLAGS=os.environ.get("XLA_FLAGS", ""),
    )


def parser(doc: str, frames: int, seed: int) -> argparse.ArgumentParser:
    """The common command line: --quick, --frames, --seed, --out."""
    p = argparse.ArgumentParser(
        description=doc, formatter_class=argparse.RawDescriptionHelpFormatter
    )
    p.add_argument("--quick", action="store_true", help="a few frames, for CI")
    p.add_argument("--frames", type=int, default=frames, help=f"frames (default {frames})")
    p.add_argument("--seed", type=int, default=seed, help=f"base seed (default {seed})")
    p.add_argument("--out", default=str(RESULTS), help="output directory (default results/)")
    return p


def centres_for(image, method: str, space, stripe: str, **kw):
    """Centres of one stripe as (N, 2) pixel coordinates (NaN where none)."""
    from cslx import segmentation as segment

    c = segment.extract(image, method, space=space, stripe=stripe, **kw)
    return segment.centres_to_pixels(c, stripe)


def draw_points(ax, uv: np.ndarray, colour: str, size: float = 1.5, label: str | None = None):
    """Scatter finite (u, v) points on an image axis."""
    ok = np.all(np.isfinite(uv), axis=1)
    ax.scatter(uv[ok, 0], uv[ok, 1], s=size, c=colour, linewidths=0, label=label)


def image_axis(ax, image, title: str | None = None, cmap: str | None = None, **kw):
    """Show an image with no ticks."""
    ax.imshow(image, cmap=cmap, **kw)
    ax.set_xticks([])
    ax.set_yticks([])
    if title:
        ax.set_title(title, fontsize=9)


def save_figure(fig, out: str, name: str, dpi: int = 110) -> str:
    """Save a Matplotlib figure as out/name and close it."""
    import matplotlib.pyplot as plt

    os.makedirs(out, exist_ok=True)
    path = os.path.join(out, name)
    fig.savefig(path, dpi=dpi, bbox_inches="tight")
    plt.close(fig)
    return path


def mono(image, space) -> np.ndarray:
    """The monochrome image of a frame in a named space or weights, as NumPy float."""
    from cslx.segmentation import monochrome_for

    return np.asarray(
        monochrome_for(image, SPACES.get(space, space) if isinstance(space, str) else space)[0]
    )


def second_pass_inputs(image, stripe: str):
    """``(centres, inputs)``: `cslx.segmentation.extract` (method "linked") of one frame and
    stripe, and what its second pass (`cslx.segmentation.robust.second_pass`) was given: the
    monochrome image, the first pass's ``pos`` / ``valid`` / ``bridged`` / ``clipped``, and
    its ``sigma`` and ``axis``. For the diagnosis scripts that re-run the second pass's
    stages (`experiments.toe_leak`, `experiments.plate_speckle`)."""
    from cslx import segmentation as seg
    from cslx.segmentation import robust

    seen = {}
    real = robust.second_pass

    def spy(mono, pos, valid, bridged, clipped=None, **kw):
        seen.update(mono=mono, pos=pos, valid=valid, bridged=bridged, clipped=clipped, **kw)
        return real(mono, pos, valid, bridged, clipped, **kw)

    robust.second_pass = spy
    try:
        centres = seg.extract(image, "linked", stripe=stripe)
    finally:
        robust.second_pass = real
    return centres, seen
