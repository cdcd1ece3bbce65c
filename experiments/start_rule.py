"""The weld-line filter's start rules against the default, on the rendered T approaches.

Each (seed, placement, nuisance) of `experiments.tracking_sequences` found in the caches
(``--cache``, repeatable; the first holding a run's file is used) is tracked by the default
tracker and by each variant of `VARIANTS` (`cslx.runtime.filter_start`), in one process,
on the same pipeline outputs (`experiments.tracking_diagnostics._share_pipeline`: the
variants change the filter only). Prints each run's scores (`tracking_sequences.score`)
where a variant changes any of them, the runs whose goal verdicts change, and per
variant the number of runs missing each goal.

    python -m experiments.start_rule --seed 7301 --also-seed 7740 --seeds 4 \\
        --cache /tmp/cslx-tracking-sequences/sequences [--frames 48]

``--bead-wide``: instead, `experiments.tracking_generality`'s bead_wide condition (22–26 mm
beads, 32 frames, clean and sunny) at ``--seed`` (its development seed 7400), each variant.

A run a variant's consensus has not decided by its last frame is named ("start
undecided"): with ``--frames 3`` that says whether frames 0–2 were enough to tell.

Results (104 development runs, fresh 7950–7953 on frames 0–2): `cslx.runtime.filter_start`.
"""

from __future__ import annotations

import dataclasses
import pathlib

from experiments.common import parser
from experiments.tracking_sequences import GOALS, NUISANCES, PLACEMENTS, make_sequence, score

#: name → `KalmanConfig` changes. The width range: the rendered beads' 12–20 mm
#: (`tracking_sequences.sequence_poses`) ± `width_tol` (20 %).
VARIANTS = {
    "agree3": dict(start_agree=3),
    "agree4": dict(start_agree=4),
    "width": dict(start_width_mm=(9.6, 24.0)),
}
KEYS = ("estimate_pct", "offset_mean_mm", "offset_max_mm", "heading_mean_deg", "t_recall_pct")


def _same(a: float, b: float) -> bool:
    return a == b or (a != a and b != b)  # NaN = NaN


def misses(s: dict) -> set[str]:
    """The goals (`tracking_sequences.GOALS` columns) a run's scores miss."""
    out = set()
    for key, cmp, bound, _ in GOALS:
        v = s[key]
        if (v < bound) if cmp == ">=" else (v > bound):
            out.add(key)
    return out


def bead_wide(seed: int, trackers_for) -> None:
    """The variants on `experiments.tracking_generality`'s bead_wide condition (module
    docstring); ``trackers_for(sensor)`` → name → tracker."""
    from experiments.tracking_generality import CONDITIONS, sequence
    from experiments.tracking_generality import score as score_rig
    from experiments.tracking_sequences import run_tracker

    trackers = None
    for nu in ("clean", "sunny"):
        seq = sequence(seed, CONDITIONS["bead_wide"], 32, nu)
        sensor = seq.pop("sensor")
        trackers = trackers or trackers_for(sensor)
        for name, tracker in trackers.items():
            obs = run_tracker(tracker, seq)
            s = score_rig(obs, seq, sensor)
            text = " ".join(f"{k} {s[k]:.4g}" for k in KEYS)
            widths = " ".join(f"{o.bead_width_mm:.1f}" for o in obs[:3])
            print(f"bead_wide {seed} {nu} [{name}] {text}; first widths {widths}", flush=True)


def main() -> None:
    p = parser(__doc__.splitlines()[0], 48, 7301)
    p.add_argument("--seeds", type=int, default=1)
    p.add_argument("--also-seed", type=int, action="append", default=[])
    p.add_argument("--cache", action="append", default=[])
    p.add_argument("--variant", action="append", choices=sorted(VARIANTS))
    p.add_argument("--bead-wide", action="store_true", help="the bead_wide condition instead")
    a = p.parse_args()
    from cslx.environment import configure

    configure()
    from cslx.runtime import Tracker
    from cslx.runtime.line_filter import KalmanConfig
    from cslx.sensor import default_sensor
    from experiments.tracking_diagnostics import _share_pipeline
    from experiments.tracking_sequences import run_tracker

    names = ("default", *(a.variant or VARIANTS))

    def trackers_for(sensor) -> dict:
        return {
            n: Tracker.from_calibration(
                sensor,
                log=lambda s: None,
                kalman=dataclasses.replace(KalmanConfig(), **VARIANTS.get(n, {})),
            )
            for n in names
        }

    if a.bead_wide:
        bead_wide(a.seed, trackers_for)
        return
    memo: dict = {}
    trackers = trackers_for(default_sensor())
    for tracker in trackers.values():
        _share_pipeline(tracker, memo)
    caches = [pathlib.Path(c) for c in a.cache or ["/tmp/cslx-tracking-sequences/sequences"]]
    seeds = [s for b in (a.seed, *a.also_seed) for s in range(b, b + a.seeds)]
    n_miss = {n: {k: 0 for k, *_ in GOALS} for n in names}
    sums = {n: dict.fromkeys(KEYS, 0.0) for n in names}
    n_runs = 0
    for seed in seeds:
        for pl in PLACEMENTS:
            for nu in NUISANCES:
                name_f = f"seq_{pl}_{nu}_{seed}_{a.frames}.npz"
                cache = next((c for c in caches if (c / name_f).exists()), None)
                if cache is None:
                    continue
                seq = make_sequence(seed, nu, pl, a.frames, cache)
                memo.clear()
                res = {n: score(run_tracker(t, seq), seq) for n, t in trackers.items()}
                n_runs += 1
                base = res["default"]
                for n, s in res.items():
                    for k in n_miss[n]:
                        n_miss[n][k] += k in misses(s)
                    for k in KEYS:
                        sums[n][k] += s[k] if s[k] == s[k] else 0.0
                    if n == "default":
                        continue
                    diff = [k for k in (*KEYS, "t_false") if not _same(s[k], base[k])]
                    if trackers[n].filter.start_beads:  # the consensus rule not yet decided
                        print(f"{seed} {pl} {nu} [{n}] start undecided at the last frame")
                    if diff:
                        text = " ".join(f"{k} {base[k]:.4g} → {s[k]:.4g}" for k in diff)
                        flag = " VERDICT" if misses(s) != misses(base) else ""
                        print(f"{seed} {pl} {nu} [{n}] {text}{flag}", flush=True)
                print(f"{seed} {pl} {nu} done", flush=True)
    for n in names:
        avg = " ".join(f"{k} {v / max(n_runs, 1):.4f}" for k, v in sums[n].items())
        print(f"[{n}] {n_runs} runs, mean over runs: {avg}; misses {n_miss[n]}", flush=True)


if __name__ == "__main__":
    main()
