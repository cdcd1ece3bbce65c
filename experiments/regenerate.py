"""Regenerate every table and figure in `results/` at one clean commit.

Each step is one committed experiment script run as `python -m experiments.<name>` in its own
process, with the configuration that `results/` documents; every output names the commit it
ran at (`cslx.provenance`). The run refuses to start when `cslx/`, `experiments/` or
`pyproject.toml` differ from HEAD (a result must be the output of a commit), and a step that
fails stops the run unless --keep-going.

    python -m experiments.regenerate --list
    python -m experiments.regenerate --out /tmp/results        # everything, ≈ 2–3 h here
    python -m experiments.regenerate --only table5 fig22 --out results

Outputs are written to --out (default `results/`); write to a scratch folder and copy when
other work shares the checkout, so that nothing half-written lands in `results/`.
"""

from __future__ import annotations

import argparse
import subprocess
import sys
import time
from dataclasses import dataclass

from experiments import common as C


@dataclass(frozen=True)
class Step:
    name: str
    module: str
    args: tuple[str, ...] = ()
    minutes: float = 1.0  # rough duration on the 2-core development machine


#: In dependency-free order, fastest first; `minutes` is what each took on this machine.
STEPS = (
    Step("fig07", "fig07_colour_spaces", minutes=1),
    Step("fig11", "fig11_med_waveforms", minutes=1),
    Step("fig12", "fig12_centres", minutes=1),
    Step("fig16_17", "fig16_17_methods", minutes=2),
    Step("fig18", "fig18_conditions", minutes=3),
    Step("fig21", "fig21_weld_profiles", minutes=2),
    Step("contact_sheet", "contact_sheet", minutes=1),
    Step("robust", "robust_extraction", ("--frames", "2"), minutes=20),
    Step("flat_wall", "flat_wall", minutes=2),
    Step("table6", "table6_segmentation", ("--frames", "64", "--time-calls", "200"), 25),
    Step("sweep_noise", "sweep_noise", minutes=15),
    Step("table5", "table5_calibration", minutes=15),
    Step("fig22", "fig22_tracking", ("--jobs", "2"), minutes=25),
    # Held-out blocks 7303–7304 and 7306–7307 (7305 is a development seed).
    Step(
        "tracking",
        "tracking_sequences",
        ("--seed", "7303", "--also-seed", "7306", "--seeds", "2"),
        30,
    ),
    Step("bench_speed", "bench_speed", minutes=20),
    Step("bench_scaling", "bench_scaling", minutes=10),
    Step("tune", "tune_differentiable", minutes=20),
)


def _command(step: Step, out: str) -> list[str]:
    return [sys.executable, "-m", f"experiments.{step.module}", *step.args, "--out", out]


def main(argv: list[str] | None = None) -> int:
    from cslx.provenance import git_sha

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--out", default=str(C.RESULTS), help="output folder (default results/)")
    p.add_argument("--only", nargs="+", choices=[s.name for s in STEPS], help="these steps")
    p.add_argument("--skip", nargs="+", choices=[s.name for s in STEPS], default=[])
    p.add_argument("--list", action="store_true", help="print the steps and exit")
    p.add_argument("--keep-going", action="store_true", help="run the rest after a failure")
    p.add_argument("--allow-dirty", action="store_true", help="run on uncommitted code")
    a = p.parse_args(argv)
    steps = [s for s in STEPS if (not a.only or s.name in a.only) and s.name not in a.skip]
    if a.list:
        for s in steps:
            print(f"{s.name:14s} ≈{s.minutes:4.0f} min  {' '.join(_command(s, a.out)[1:])}")
        return 0
    sha = git_sha()
    if sha.endswith("-dirty") and not a.allow_dirty:
        print(
            f"experiments.regenerate: the code differs from HEAD ({sha}); commit it first "
            "(results must name the commit that produced them) or pass --allow-dirty",
            file=sys.stderr,
        )
        return 2
    total = sum(s.minutes for s in steps)
    print(f"regenerating {len(steps)} results at {sha} into {a.out} (≈ {total:.0f} min)")
    failed = []
    for i, s in enumerate(steps, 1):
        t0 = time.perf_counter()
        print(f"[{i}/{len(steps)}] {s.name}: {' '.join(_command(s, a.out)[1:])}", flush=True)
        rc = subprocess.run(_command(s, a.out)).returncode
        print(f"[{i}/{len(steps)}] {s.name}: exit {rc} after {time.perf_counter() - t0:.0f} s")
        if rc:
            failed.append(s.name)
            if not a.keep_going:
                break
        if git_sha() != sha:
            print("experiments.regenerate: the code changed during the run; stopping")
            return 3
    if failed:
        print(f"failed: {', '.join(failed)}", file=sys.stderr)
        return 1
    return 0


if __name__ == "__main__":
    sys.exit(main())
