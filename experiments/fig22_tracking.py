"""Figure 22: closed-loop weld tracking through a T-intersection, for every nuisance kind.

Runs `cslx.sim.closed_loop.run_closed_loop` (the runtime's per-frame loop, the path
controller and the pty robot simulator; its docstring describes the loop and the error
measure) once per nuisance kind (clean, sunny, glare, shadow), each along the stem, through
the T and `after_turn_frames` frames along the crossing weld, and writes
results/fig22_tracking.csv (one row per frame, with its nuisance), .md (per nuisance: turn
completed, mean / p95 / max tracking error over all counted frames, provenance and the
machine load) and .png (welds and robot trail, error over time, one row per nuisance).

The seed (2302) is held out: the controller's junction gate, its re-acquisition and the turn
(issue 12) were developed on seed 2201's runs, which this figure used before; no development
ran 2302.
"""

from __future__ import annotations

import concurrent.futures
import os
import pathlib
import pickle

from experiments.common import RESULTS, load_average, parser

NUISANCES = ("clean", "sunny", "glare", "shadow")

DEFAULTS = dict(
    n_frames=420,
    seed=2302,
    fps=20.0,
    start_before_mm=220.0,
    start_offset_mm=4.0,
    start_heading_deg=3.0,
    turn_rate=0.5,
    # the start transient left out of `steady_*` (cslx.sim.closed_loop.SETTLE_S says why)
    settle_s=1.5,
    after_turn_frames=40,
)

KEYS = (
    "n_frames",
    "n_counted",
    "turns_completed",
    "mean_error_mm",
    "p95_error_mm",
    "max_error_mm",
    "steady_mean_error_mm",
    "steady_max_error_mm",
    "stem_steady_mean_error_mm",
    "stem_steady_max_error_mm",
    "after_turn_mean_error_mm",
    "after_turn_max_error_mm",
    "mean_abs_estimation_error_mm",
    "max_abs_estimation_error_mm",
    "turn_stop_x_mm",
    "turn_junction_x_error_mm",
    "junction_frames",
    "blind_stops",
    "step_median_ms",
    "loop_fps_with_render",
)


def _one(nuisance: str, config: dict, parts: pathlib.Path | None = None) -> dict:
    from cslx.environment import configure

    configure()
    from cslx.sim.closed_loop import run_closed_loop

    result = run_closed_loop(nuisance=nuisance, **config)
    result["load_after"] = load_average()
    if parts is not None:  # each run is kept as it completes (`--collect` writes from them)
        parts.mkdir(parents=True, exist_ok=True)
        tmp = parts / f"{nuisance}.pkl.tmp"
        tmp.write_bytes(pickle.dumps(result))
        os.replace(tmp, parts / f"{nuisance}.pkl")
    return result


def collect(out_dir: str | os.PathLike | None = None, **config) -> dict[str, dict]:
    """Write the outputs from the runs kept so far (out_dir/fig22_parts/*.pkl)."""
    out = pathlib.Path(out_dir) if out_dir else RESULTS
    parts = out / "fig22_parts"
    results = {
        n: pickle.loads((parts / f"{n}.pkl").read_bytes())
        for n in NUISANCES
        if (parts / f"{n}.pkl").exists()
    }
    _write(results, {**DEFAULTS, **config}, out, "see each run", "several")
    return results


def main(
    out_dir: str | os.PathLike | None = None,
    nuisances=NUISANCES,
    jobs: int = 1,
    **config,
) -> dict[str, dict]:
    """Run the closed loop per nuisance with `config` over DEFAULTS; write the results.

    Returns {nuisance: summary (the per-frame rows under "rows")}.
    """
    cfg = {**DEFAULTS, **config}
    load_before = load_average()
    out = pathlib.Path(out_dir) if out_dir else RESULTS
    parts = out / "fig22_parts"
    if jobs > 1:
        with concurrent.futures.ProcessPoolExecutor(jobs) as pool:
            futures = {n: pool.submit(_one, n, cfg, parts) for n in nuisances}
            results = {n: f.result() for n, f in futures.items()}
    else:
        results = {n: _one(n, cfg, parts) for n in nuisances}
    _write(results, cfg, out, load_before, jobs)
    return results


def _write(results: dict, config: dict, out_dir: pathlib.Path, load_before: str, jobs) -> None:
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    from cslx.provenance import md_table, provenance, provenance_md, write_csv
    from cslx.sim.closed_loop import plot_closed_loop

    out_dir.mkdir(parents=True, exist_ok=True)
    rows = [r for res in results.values() for r in res["rows"]]
    write_csv(str(out_dir / "fig22_tracking.csv"), rows)
    fig, axes = plt.subplots(len(results), 2, figsize=(13, 4.6 * len(results)), squeeze=False)
    for (name, res), pair in zip(results.items(), axes, strict=True):
        plot_closed_loop(res, axes=pair, label=f"{name}: ")
    fig.tight_layout()
    fig.savefig(out_dir / "fig22_tracking.png", dpi=100)
    plt.close(fig)
    table = [{"nuisance": n, **{k: res[k] for k in KEYS}} for n, res in results.items()]
    done = all(res["turns_completed"] >= 1 for res in results.values())
    text = [
        "# Figure 22: closed-loop weld tracking through a T-intersection (simulated)\n\n",
        "The robot simulator (lock-step, over a real pty and the binary protocol) follows a "
        "rendered weld with the runtime's per-frame loop, detects the T-intersection on the "
        "vertical stripe, turns 90° left in place and follows the crossing weld, once per "
        "nuisance kind. Tracking error: distance from the look-ahead point (horizontal "
        "stripe on the robot's axis) to the true centre line of the weld followed, in every "
        "frame where the stripe is on that weld and the robot is not turning (`n_counted` "
        "of `n_frames`); mean, p95 and max are over all those frames, including the "
        f"response to the initial error ({config['start_offset_mm']} mm, "
        f"{config['start_heading_deg']}°); `steady_*` leave out the first "
        f"{config['settle_s']:g} s (the start transient: the designed initial error "
        "enters the max of all frames); `stem_steady_*` cover the stem after those "
        f"{config['settle_s']:g} s, `after_turn_*` every counted frame on the crossing weld, "
        "the re-acquisition right after the turn included. The paper reports < 2 mm average "
        "tracking error. "
        "`blind_stops`: times the controller stopped the robot for lack of a confident "
        "observation.\n\n",
        f"Turn completed in every nuisance kind run ({', '.join(results)}): "
        f"**{'yes' if done else 'no'}**."
        + (
            f" Not run this time: {', '.join(n for n in NUISANCES if n not in results)}."
            if len(results) < len(NUISANCES)
            else ""
        )
        + "\n\n",
        md_table(table, ["nuisance", *KEYS]),
        "\n\nWelds: "
        + "; ".join(
            f"{n}: " + ", ".join(f"{k} {v:.1f}" for k, v in res["welds"].items())
            for n, res in results.items()
        )
        + ".\n\n",
        f"Timings (`step_median_ms`: `Tracker.step` alone; `loop_fps_with_render`: the loop "
        f"with rendering) were taken on a shared 2-core VM with {jobs} run(s) in parallel; "
        f"load average (1/5/15 min) before: {load_before}, after each run: "
        + ", ".join(f"{n} {res['load_after']}" for n, res in results.items())
        + ". They are upper bounds.\n",
        "\n## Provenance\n",
        provenance_md(provenance({**config, "nuisances": list(results), "jobs": jobs})),
    ]
    (out_dir / "fig22_tracking.md").write_text("".join(text), encoding="utf-8")


if __name__ == "__main__":
    p = parser(__doc__.splitlines()[0], DEFAULTS["n_frames"], DEFAULTS["seed"])
    p.add_argument("--nuisance", action="append", choices=NUISANCES, help="(repeatable)")
    p.add_argument("--jobs", type=int, default=1, help="runs in parallel processes")
    p.add_argument("--collect", action="store_true", help="write outputs from the kept runs")
    a = p.parse_args()
    n = 60 if a.quick else a.frames
    if a.collect:
        res = collect(out_dir=a.out, n_frames=n, seed=a.seed)
    else:
        res = main(
            out_dir=a.out,
            nuisances=tuple(a.nuisance or NUISANCES),
            jobs=a.jobs,
            n_frames=n,
            seed=a.seed,
        )
    for name, r in res.items():
        print(
            f"{name}: turns {r['turns_completed']}; tracking error mean {r['mean_error_mm']:.2f}"
            f" p95 {r['p95_error_mm']:.2f} max {r['max_error_mm']:.2f} mm over "
            f"{r['n_counted']} of {r['n_frames']} frames"
        )
