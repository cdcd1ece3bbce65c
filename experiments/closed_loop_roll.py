"""The closed loop (Figure 22's run) on a rig whose cross projector is rolled (issue 12).

On the default rig the horizontal stripe crosses the wall straight across the robot's
axis, at x_ref = 150 mm, where the tracker's weld line is referenced and where the
controller's look-ahead (`ControllerConfig.lookahead_mm`) sits. Rolled about its axis the
projector draws a leaning stripe: it crosses the robot's axis 155 / 160 / 167 mm ahead at
8 / 15 / 25° (`cslx.runtime.line_filter.stripe_x_on_axis`), and the tracker reports the
offset there (`offset_at_stripe`). The turn at a T ends on the observed offset of the
crossing weld through the look-ahead's lever (`PathController._finish_on_weld`), so this
script runs `cslx.sim.closed_loop.run_closed_loop` on the rolled rig of
`experiments.tracking_generality.rig_sensor` with the look-ahead at the stripe
(``axis``, `Tracker.lookahead_mm`, the default) and at x_ref (``x_ref``, before), one
compiled tracker for both, and prints Figure 22's summary per run.

    python -m experiments.closed_loop_roll --roll 25 --seed 2201 --nuisance clean

Seeds: Figure 22's development seeds (2201, 2203, 2204), never its held-out 2302.
"""

from __future__ import annotations

import argparse

from experiments.fig22_tracking import DEFAULTS

KEYS = (
    "turns_completed",
    "n_counted",
    "mean_error_mm",
    "max_error_mm",
    "steady_mean_error_mm",
    "after_turn_mean_error_mm",
    "after_turn_max_error_mm",
    "turn_stop_x_mm",
    "blind_stops",
    "step_median_ms",
)


def main(roll_deg: float, seed: int, nuisances, variants) -> list[dict]:
    from cslx.environment import configure

    configure()
    from cslx.runtime import Tracker
    from cslx.sim.closed_loop import run_closed_loop
    from experiments.tracking_generality import rig_sensor

    sensor = rig_sensor(roll_deg=roll_deg)
    tracker = Tracker.from_calibration(sensor, log=lambda s: None)
    axis = tracker.lookahead_mm
    print(f"roll {roll_deg}°: x_ref {tracker.x_ref:.2f} mm, stripe on the axis {axis:.2f} mm")
    out = []
    for nuisance in nuisances:
        for variant in variants:
            tracker.lookahead_mm = axis if variant == "axis" else tracker.x_ref
            cfg = {**DEFAULTS, "seed": seed}
            res = run_closed_loop(nuisance=nuisance, tracker=tracker, sensor=sensor, **cfg)
            row = dict(roll_deg=roll_deg, seed=seed, nuisance=nuisance, lookahead=variant)
            row.update({k: res[k] for k in KEYS})
            print(
                ", ".join(
                    f"{k} {v:.3f}" if isinstance(v, float) else f"{k} {v}" for k, v in row.items()
                )
            )
            out.append(row)
    tracker.lookahead_mm = axis
    return out


if __name__ == "__main__":
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--roll", type=float, default=25.0, help="projector roll, degrees")
    p.add_argument("--seed", type=int, default=2201)
    p.add_argument("--nuisance", action="append", help="(repeatable; default clean)")
    p.add_argument("--variant", action="append", choices=("axis", "x_ref"))
    a = p.parse_args()
    main(a.roll, a.seed, a.nuisance or ["clean"], a.variant or ["x_ref", "axis"])
