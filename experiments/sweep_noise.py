"""Error vs nuisance strength per method: where does each segmentation method break?

Starting from the "sunny" preset of `cslx.sim.NUISANCES`, one knob is varied at a time:
sunlight (`sun`, with the steel's broad sheen scaled in proportion, as both come from the
sun), specular glints on the bead (`glint`), and laser speckle contrast (`speckle`). Every
level renders the same scenes (frame i: world, pose and noise from `default_rng([seed, i])`,
straight and T scenes alternating), so the curves differ only by the knob. The horizontal
stripe is scored with CM, LA, QA, AA, Steger (no MED) and MED, in R and R−G (the vertical
stripe is left out: vertical MED costs seconds per frame on this CPU, see Table 6).

Writes `results/sweep_noise.csv` and `results/sweep_noise.png`.
"""

from __future__ import annotations

import os
import time

import numpy as np

from experiments import common as C  # noqa: E402

_BREAK_NOTE = (
    "First level at which the median error exceeds 0.5 mm, or the detection rate falls below "
    "80 % of the method's own detection rate at the weakest level (that rate in brackets: "
    'LA/QA/AA drop columns even without nuisance); "> max": never within the sweep.'
)
METHODS = ("cm", "la", "qa", "aa", "steger", "med")
LEVELS = {
    "sun": (0.0, 150.0, 300.0, 600.0, 1000.0, 1600.0),
    "glint": (0.0, 300.0, 1000.0, 3000.0, 6000.0, 12000.0),
    "speckle": (0.0, 0.25, 0.5, 0.75, 1.0),
}


def _nuisance(knob: str, level: float):
    from cslx import sim as synth

    base = synth.NUISANCES["sunny"]
    if knob == "sun":
        return base._replace(sun=level, sheen=base.sheen * level / max(base.sun, 1e-9))
    return base._replace(**{knob: level})


def _frame(nz, seed: int, i: int, sensor):
    from cslx import sim as synth

    kind = C.KINDS[i % 2]
    rng = np.random.default_rng([seed, i])
    world = synth.random_world(kind, rng)
    pose = synth.random_pose(world, kind, rng, sensor)
    return synth.render_frame(sensor, world, pose, nz, seed=int(rng.integers(2**31)))


def _breaks(rows, levels):
    """Per knob and space, the first level where each method breaks (see the .md)."""
    out = []
    for knob, vs in levels.items():
        for space in ("r-g", "r"):
            b = {"knob": knob, "space": C.SPACE_LABEL[space]}
            for m in METHODS:
                mine = [x for x in rows if (x["knob"], x["space"], x["method"]) == (knob, space, m)]
                mine.sort(key=lambda x: x["level"])
                d0 = mine[0]["detection_rate"]
                bad = [
                    x["level"]
                    for x in mine
                    if not x["median_mm"] <= 0.5 or x["detection_rate"] < 0.8 * d0
                ]
                b[C.METHOD_LABEL[m]] = (
                    f"{min(bad):g}" if bad else f"> {max(vs):g}"
                ) + f" [{d0:.2f}]"
            out.append(b)
    return out


def _replot(out):
    import csv
    import re

    from cslx.provenance import md_table

    with open(os.path.join(out, "sweep_noise.csv"), encoding="utf-8") as f:
        rows = [
            {k: (v if k in ("knob", "space", "method") else float(v)) for k, v in r.items()}
            for r in csv.DictReader(f)
        ]
    _plot(rows, out)
    levels = {k: v for k, v in LEVELS.items() if any(r["knob"] == k for r in rows)}
    table = md_table(
        _breaks(rows, levels), ["knob", "space"] + [C.METHOD_LABEL[m] for m in METHODS]
    )
    path = os.path.join(out, "sweep_noise.md")
    with open(path, encoding="utf-8") as f:
        md = f.read()
    md = re.sub(
        r"## Where each method breaks.*?## Provenance",
        "## Where each method breaks\n\n"
        + _BREAK_NOTE
        + "\n\n"
        + table
        + "\n(re-derived from sweep_noise.csv)\n\n## Provenance",
        md,
        flags=re.S,
    )
    with open(path, "w", encoding="utf-8") as f:
        f.write(md)
    print(table)
    return rows


def _plot(rows, out):
    import matplotlib.pyplot as plt

    fig, axes = plt.subplots(3, len(LEVELS), figsize=(5.2 * len(LEVELS), 10), sharex="col")
    metrics = (
        ("median_mm", "median error (mm)", True),
        ("mean_mm", "mean error (mm)", True),
        ("detection_rate", "detection rate", False),
    )
    for c, knob in enumerate(LEVELS):
        for r, (key, label, log) in enumerate(metrics):
            ax = axes[r, c]
            for m in METHODS:
                for space, ls in (("r-g", "-"), ("r", "--")):
                    pts = [
                        (x["level"], x[key])
                        for x in rows
                        if x["knob"] == knob and x["method"] == m and x["space"] == space
                    ]
                    if not pts:
                        continue
                    xs, ys = zip(*pts, strict=True)
                    ax.plot(
                        xs,
                        ys,
                        ls,
                        color=C.METHOD_COLOUR[m],
                        marker="o",
                        ms=3,
                        lw=1.2,
                        label=f"{C.METHOD_LABEL[m]} {C.SPACE_LABEL[space]}",
                    )
            if log:
                ax.set_yscale("log")
                ax.axhline(1.0, color="k", lw=0.5, ls=":")
            else:
                ax.set_ylim(-0.02, 1.02)
            ax.set_ylabel(label, fontsize=8)
            ax.tick_params(labelsize=7)
            ax.grid(alpha=0.3, which="both", lw=0.3)
        axes[0, c].set_title(f"varying {knob} (others: 'sunny' preset)", fontsize=9)
        axes[-1, c].set_xlabel(
            knob
            + (
                " (DN; sheen scaled with it)"
                if knob == "sun"
                else " (DN)"
                if knob == "glint"
                else " contrast"
            ),
            fontsize=8,
        )
    h, lab = axes[0, 0].get_legend_handles_labels()
    fig.legend(h, lab, loc="lower center", ncol=6, fontsize=7, frameon=False)
    fig.suptitle(
        "Horizontal-stripe error vs nuisance strength (solid: R−G, dashed: R; dotted line: 1 mm)",
        fontsize=10,
    )
    fig.tight_layout(rect=(0, 0.05, 1, 0.97))
    return C.save_figure(fig, out, "sweep_noise.png")


def main(
    frames: int = 6,
    seed: int = 21,
    quick: bool = False,
    out: str = str(C.RESULTS),
    replot: bool = False,
):
    """Run the sweep, write CSV + PNG + MD note, return the rows."""
    from tqdm import tqdm

    from cslx.provenance import md_table, provenance, provenance_md, write_csv
    from cslx.sensor import default_sensor

    if replot:  # re-derive the plot and the break table from a finished run's CSV
        return _replot(out)
    levels = {k: (v[0], v[-1]) for k, v in LEVELS.items()} if quick else LEVELS
    frames = min(frames, 2) if quick else frames
    sensor = default_sensor()
    rows = []
    t0 = time.perf_counter()
    todo = [(k, lv) for k, vs in levels.items() for lv in vs]
    for knob, level in tqdm(todo, desc="sweep levels"):
        nz = _nuisance(knob, level)
        pools = {(sp, m): C.Pool() for sp in ("r", "r-g") for m in METHODS}
        for i in range(frames):
            image, gt = _frame(nz, seed, i, sensor)
            for (space, method), pool in pools.items():
                uv = C.centres_for(image, method, C.SPACES[space], "h")
                pool.add(*C.point_errors(uv, gt["h_xyz"], sensor, 0))
        for (space, method), pool in pools.items():
            rows.append(dict(knob=knob, level=level, space=space, method=method, **pool.summary()))
    elapsed = time.perf_counter() - t0
    config = dict(
        frames=frames,
        seed=seed,
        quick=quick,
        base="sunny",
        stripe="h",
        levels={k: list(v) for k, v in levels.items()},
    )
    prov = provenance(config)
    fields = [
        "knob",
        "level",
        "space",
        "method",
        "frames",
        "mean_mm",
        "median_mm",
        "p95_mm",
        "mean_px",
        "detection_rate",
        "gross_rate",
        "n_gt",
        "n_matched",
    ]
    write_csv(os.path.join(out, "sweep_noise.csv"), rows, fields)
    path = _plot(rows, out)
    brk = _breaks(rows, levels)
    md = [
        "# Error vs nuisance strength (horizontal stripe)",
        "",
        f"{frames} frames per level (straight and T scenes alternating, the same scenes at every "
        f"level, seed {seed}), {elapsed / 60:.1f} min. Plot: `sweep_noise.png`; all numbers: "
        "`sweep_noise.csv`.",
        "",
        "## Where each method breaks",
        "",
        _BREAK_NOTE,
        "",
        md_table(brk, ["knob", "space"] + [C.METHOD_LABEL[m] for m in METHODS]),
        "",
        "## Provenance",
        "",
        provenance_md(prov),
    ]
    with open(os.path.join(out, "sweep_noise.md"), "w", encoding="utf-8") as f:
        f.write("\n".join(md))
    print(f"wrote {path} and sweep_noise.{{csv,md}} in {elapsed:.0f} s")
    print(md_table(brk, ["knob", "space"] + [C.METHOD_LABEL[m] for m in METHODS]))
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 6, 21)
    a.add_argument("--replot", action="store_true", help="redo plot + break table from the CSV")
    args = a.parse_args()
    main(frames=args.frames, seed=args.seed, quick=args.quick, out=args.out, replot=args.replot)
