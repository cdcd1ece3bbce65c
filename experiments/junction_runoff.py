"""The run-off test of the crossing detector, before / after, on the rendered T approaches.

`cslx.runtime.junction` ("run-off test"): a crossing candidate without plate on its near
side loses to a farther one with plate on both sides, and no crossing cap is taller than a
half disc (`WeldConfig.crossing_bump_mm`, `crossing_cap_max`). For each (seed, placement,
nuisance) of `experiments.tracking_sequences` this runs the tracker with both tests off
(`before`) and records, per frame, the vertical stripe's points, the horizontal stripe's
median x_r (the crossing mask of `cslx.runtime.weld.weld_features`) and the odometry. It
then replays `crossing_feature` on the recorded points under each detector setting and
`Tracker._junction` on its sightings (the junction output feeds nothing else in the
tracker, so offset and heading scores cannot change): the `before` replay must reproduce
the tracker's T scores on every run (asserted). Recordings are cached under ``--record``.

    python -m experiments.junction_runoff --seed 1205 [--also-seed S ...] --cache DIR

What it printed (dev seeds 7301, 7302, 7305, 1201–1206, 7740–7743, every nuisance; T recall
% / false T frames; the numbers per run in `cslx.runtime.junction`'s "run-off test"): flank
52 runs, runs missing a T goal 5 → 4, false T frames 30 → 20, mean recall 97.89 → 98.24 %;
beside (1204–1206 not run) 40 runs, 3 → 5, 4 → 6, 99.17 → 98.92 %. Fresh seeds 7960–7963,
once (32 runs): 3 → 2, 9 → 3, 98.94 → 99.67 %.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib
import pickle
import types

import numpy as np

from experiments.common import parser
from experiments.junction_errors import t_scores
from experiments.tracking_sequences import NUISANCES, PLACEMENTS, make_sequence, score

INF = float("inf")


def settings():
    """Detector settings replayed: name → `WeldConfig` (the tracker's, tests on / off)."""
    from cslx.runtime.pipeline_config import tracking_config

    weld = tracking_config().weld
    off = dataclasses.replace
    return {
        "before": off(weld, crossing_cap_max=INF, crossing_bump_mm=INF),
        "cap only": off(weld, crossing_bump_mm=INF),
        "run-off only": off(weld, crossing_cap_max=INF),
        "after": weld,
        "bump 0.8 mm": off(weld, crossing_bump_mm=0.8),
        "bump 1.2 mm": off(weld, crossing_bump_mm=1.2),
        "cap 0.8": off(weld, crossing_cap_max=0.8),
    }


def record(seeds, placements, nuisances, cache: pathlib.Path, out: pathlib.Path) -> dict:
    """Run the tracker with the `before` detector; per run its frames' junction inputs."""
    from cslx.environment import configure

    configure()
    from cslx.runtime import Tracker
    from cslx.runtime.pipeline_config import tracking_config
    from cslx.sensor import default_sensor

    frames: list[dict] = []

    class Recording(Tracker):
        def _measure(self, frame, obs, d):
            step = self._compiled
            if not getattr(step, "recording", False):

                def wrapped(rgb, *state, step=step):
                    res = step(rgb, *state)
                    x = np.asarray(res[1], np.float32)[:, 0]
                    self._x_h = float(np.nanmedian(x)) if np.isfinite(x).any() else math.nan
                    return res

                wrapped.recording = True
                self._compiled = wrapped
            return super()._measure(frame, obs, d)

        def _junction(self, obs, raw, points_v):
            scalars = {k: float(v) for k, v in raw.items() if np.ndim(v) == 0}
            pts = np.asarray(points_v).copy()
            frames.append(dict(frame=obs.frame, raw=scalars, points=pts, xh=self._x_h))
            super()._junction(obs, raw, points_v)

    pc = tracking_config()
    pc = dataclasses.replace(pc, weld=settings()["before"])
    tracker = Recording.from_calibration(default_sensor(), pc, log=lambda s: None)
    out.mkdir(parents=True, exist_ok=True)
    runs = {}
    for seed in seeds:
        for placement in placements:
            for nuisance in nuisances:
                path = out / f"{seed}_{placement}_{nuisance}.pkl"
                if path.exists():
                    runs[seed, placement, nuisance] = pickle.loads(path.read_bytes())
                    continue
                seq = make_sequence(seed, nuisance, placement, 48, cache)
                frames.clear()
                tracker.reset()
                obs = []
                for i, frame in enumerate(seq["frames"]):
                    odo = (float(seq["odo_d"][i]), float(seq["odo_delta"][i])) if i else None
                    obs.append(tracker.step(frame, dt=0.05, odometry=odo))
                by_frame = {f["frame"]: f for f in frames}
                moves = [(0.0, 0.0)] + [
                    (float(seq["odo_d"][i]), float(seq["odo_delta"][i])) for i in range(1, len(obs))
                ]
                run = dict(
                    frames=[by_frame.get(i) for i in range(len(obs))],
                    moves=moves,
                    score=score(obs, seq),
                    truth=np.asarray(seq["junction_x_mm"]),
                    bar_width=float(seq["sizes"][2]),
                    x_ref=tracker.x_ref,
                )
                path.write_bytes(pickle.dumps(run))
                runs[seed, placement, nuisance] = run
    return runs


_DETECTORS: dict = {}


def _detector(weld):
    """The compiled detector for one `WeldConfig` (compiled once per setting, not per run)."""
    import jax
    import jax.numpy as jnp

    from cslx.runtime.junction import crossing_feature

    key = repr(weld)
    if key not in _DETECTORS:

        def detect(P, valid, x_h):
            away = jnp.abs(P[:, 0] - x_h) > weld.crossing_mask_mm
            keep = valid & (away | ~jnp.isfinite(x_h))
            fv = crossing_feature(P, keep, weld, one_call=True)
            junction = fv.found & (fv.confidence >= weld.junction_min_confidence)
            return junction, fv.position, fv.height, fv.width

        _DETECTORS[key] = jax.jit(detect)
    return _DETECTORS[key]


def sightings(run: dict, weld) -> list:
    """`crossing_feature` with ``weld`` on each recorded frame, masked as `weld_features`
    masks it: (junction, x_r, height, width) per frame, None where the tracker refused it."""
    import jax.numpy as jnp

    detect = _detector(weld)
    out = []
    for fr in run["frames"]:
        if fr is None:
            out.append(None)
            continue
        P = np.asarray(fr["points"], np.float32)
        valid = np.isfinite(P[:, 0])
        res = detect(jnp.asarray(np.nan_to_num(P)), jnp.asarray(valid), jnp.float32(fr["xh"]))
        out.append(tuple(float(v) for v in res))
    return out


def replay(run: dict, sights: list) -> tuple[float, int]:
    """`Tracker._junction` over the run with these sightings: (T recall %, false T frames)."""
    from cslx.runtime.junction_track import JunctionTrack
    from cslx.runtime.line_filter import KalmanConfig
    from cslx.runtime.tracker import Tracker

    class Host(Tracker):
        """Only the tracker's junction state: `Tracker._junction` as the tracker runs it."""

        def __init__(self, kalman, x_ref):  # no pipeline, no compile
            self.kalman = kalman
            self._junctions = JunctionTrack.from_config(kalman, x_ref)

    host = Host(KalmanConfig(), run["x_ref"])
    rep = []
    for i, fr in enumerate(run["frames"]):
        if i:
            host._junctions.move(*run["moves"][i])
        if fr is None:
            rep.append(math.nan)
            continue
        j, x, h, w = sights[i]
        raw = dict(fr["raw"], junction=j, v_x_mm=x, v_height_mm=h, v_width_mm=w)
        obs = types.SimpleNamespace(frame=fr["frame"], junction=False, junction_x_mm=math.nan)
        host._junction(obs, raw, fr["points"])
        rep.append(obs.junction_x_mm if obs.junction else math.nan)
    return t_scores(np.array(rep), run["truth"], run["bar_width"])


def main(seeds, placements, nuisances, cache, out) -> None:
    runs = record(seeds, placements, nuisances, pathlib.Path(cache), pathlib.Path(out))
    res = {}
    for name, weld in settings().items():
        for key, run in runs.items():
            res[name, key] = replay(run, sightings(run, weld))
            if name == "before":
                s = run["score"]
                recall, false = res[name, key]
                assert (recall == s["t_recall_pct"] or math.isnan(recall)) and false == s["t_false"]
        vals = [res[name, k] for k in runs]
        bad = [f"{'/'.join(map(str, k))} {r:.1f}/{f}" for k, (r, f) in zip(runs, vals, strict=True)]
        bad = [b for b, (r, f) in zip(bad, vals, strict=True) if r < 90.0 or f > 0]
        mean = np.nanmean([r for r, _ in vals])
        false = sum(f for _, f in vals)
        print(
            f"{name}: {len(runs)} runs, T recall mean {mean:.2f} %, false T frames {false}, "
            f"{len(bad)} runs miss a T goal: {bad}",
            flush=True,
        )
    for key in runs:
        row = [res[n, key] for n in settings()]
        if len(set(row)) > 1:
            text = " ".join(f"{n}={r:.1f}/{f}" for n, (r, f) in zip(settings(), row, strict=True))
            print(" ", "/".join(map(str, key)), text)


if __name__ == "__main__":
    p = parser(__doc__.splitlines()[0], 48, 1205)
    p.add_argument("--also-seed", type=int, action="append", default=[], help="(repeatable)")
    p.add_argument("--cache", default="/tmp/cslx-tracking-sequences/sequences")
    p.add_argument("--record", default="/tmp/cslx-junction-runoff", help="recordings")
    p.add_argument("--placement", action="append", choices=PLACEMENTS, help="(repeatable)")
    p.add_argument("--nuisance", action="append", choices=NUISANCES, help="(repeatable)")
    a = p.parse_args()
    main(
        (a.seed, *a.also_seed),
        tuple(a.placement or PLACEMENTS),
        tuple(a.nuisance or NUISANCES),
        a.cache,
        a.record,
    )
