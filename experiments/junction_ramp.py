"""The crossing detector's ramp test replayed on recorded approaches (issue 12, ``cross_toe``).

Runs the default tracker once per sequence, records each frame's stripe points and
odometry, then replays, per `WeldConfig.crossing_ramp_max` value, the crossing detector
(`cslx.runtime.junction.crossing_feature` on the recorded vertical stripe, masked near the
horizontal stripe as `cslx.runtime.weld.weld_features` does) and `JunctionTrack` as
`Tracker._junction` drives it (cut by the view, the stripe's line for ``bar_slope``). The
junction output feeds nothing else, so the offsets are those of the run, and with the
tracker's own setting the replay reproduced its sightings and T scores exactly (every run of
the evidence in `cslx.runtime.junction`'s docstring). Sequences: the development approaches of
`experiments.tracking_sequences` (``--placement``) or the conditions of
`experiments.tracking_generality` (``--condition``, fresh seeds).

    python -m experiments.junction_ramp --condition cross_toe --seed 7400 --seeds 21 \\
        --nuisance clean --nuisance sunny --ramp inf --ramp 0.4

Prints per run: T recall % / false T frames per ramp value (per variant; after the first,
also the frames whose report differs from the first variant's), then the totals;
``--variant`` replays `JunctionTrack` with overrides, e.g. ``bar_min_points=6`` (issue 12's
T at 120°, `experiments.tracking_generality`), all on the same recorded frames;
``--record-cache DIR`` keeps the recorded runs, so another variant skips the tracker.
"""

from __future__ import annotations

import dataclasses
import math
import pathlib
import pickle

import numpy as np

from experiments.common import parser


def parse_overrides(text: str) -> dict:
    """'key=value,key=value' → `JunctionTrack` keyword overrides ('-': none); values are
    Python literals."""
    import ast

    if text.strip() in ("", "-"):
        return {}
    return {
        k.strip(): ast.literal_eval(v.strip())
        for k, v in (kv.split("=", 1) for kv in text.split(","))
    }


def recording_tracker(sensor):
    """A `Tracker` that keeps, per frame it runs the junction logic on, the vertical and
    horizontal stripes' points (what `Tracker._junction` and the detector see)."""
    from cslx.runtime import Tracker

    class Recording(Tracker):
        frames: dict = {}

        @property
        def _compiled(self):
            step = self.__dict__["_step"]

            def wrapped(*args):
                out = step(*args)
                self._points_h = np.asarray(out[1]).copy()
                return out

            return wrapped

        @_compiled.setter
        def _compiled(self, f):
            self.__dict__["_step"] = f

        def _junction(self, obs, raw, points_v):
            self.frames[obs.frame] = (np.asarray(points_v).copy(), self._points_h)
            super()._junction(obs, raw, points_v)

    return Recording.from_calibration(sensor, log=lambda s: None)


def record(tracker, seq: dict) -> dict:
    """The recording tracker over `seq`: observations, recorded points and odometry."""
    tracker.reset()
    tracker.frames = {}
    obs = []
    for i, frame in enumerate(seq["frames"]):
        odo = (float(seq["odo_d"][i]), float(seq["odo_delta"][i])) if i else None
        obs.append(tracker.step(frame, dt=0.05, odometry=odo))
    moves = [(0.0, 0.0)] + [
        (float(seq["odo_d"][i]), float(seq["odo_delta"][i])) for i in range(1, len(obs))
    ]
    return dict(frames=[tracker.frames.get(i) for i in range(len(obs))], moves=moves, obs=obs)


def sightings(run: dict, config) -> list:
    """`crossing_feature` per recorded frame under `config` (a `WeldConfig`)."""
    import jax
    import jax.numpy as jnp

    from cslx.runtime.junction import crossing_feature

    fn = jax.jit(lambda p, v, c: crossing_feature(p, v, c, one_call=True))
    out = []
    for fr in run["frames"]:
        if fr is None:
            out.append(None)
            continue
        pv, ph = fr
        valid = np.all(np.isfinite(pv), 1)
        x_h = np.nanmedian(ph[:, 0]) if np.isfinite(ph[:, 0]).any() else math.nan
        keep = valid & ((np.abs(pv[:, 0] - x_h) > config.crossing_mask_mm) | ~np.isfinite(x_h))
        f = fn(jnp.asarray(np.where(valid[:, None], pv, 0.0), jnp.float32), keep, config)
        found = bool(f.found) and float(f.confidence) >= config.junction_min_confidence
        out.append((found, float(f.position), float(f.height), float(f.width)))
    return out


def replay(run: dict, sights: list, kalman, x_ref: float, **track_kw) -> np.ndarray:
    """`JunctionTrack` over the recorded frames as `Tracker._junction` drives it
    (`track_kw`: `JunctionTrack.from_config` overrides)."""
    from cslx.runtime.junction_track import JunctionTrack, cut_by_view
    from cslx.runtime.line_filter import fit_line

    c = kalman
    track = JunctionTrack.from_config(c, x_ref, **track_kw)
    rep = []
    for i, (fr, s) in enumerate(zip(run["frames"], sights, strict=True)):
        if i:
            track.move(*run["moves"][i])
        if fr is None:
            rep.append(math.nan)
            continue
        pv = fr[0]
        found, x, h, w = s
        x = x if found and h >= c.junction_min_height_mm else None
        xs = pv[:, 0][np.isfinite(pv[:, 0])]
        extent = (float(xs.min()), float(xs.max())) if xs.size else None
        if x is not None and cut_by_view(x, w, extent, c.junction_cut_margin_mm):
            x = None
        ys = pv[:, 1][np.isfinite(pv[:, 1])]
        line = None
        xy = pv[np.all(np.isfinite(pv[:, :2]), 1), :2]
        if c.junction_bar_slope and len(xy) >= 10 and np.ptp(xy[:, 0]) > 0:
            line = fit_line(xy[:, 0], xy[:, 1])  # as `Tracker._junction`
        y = float(np.median(ys)) if ys.size else None
        rep.append(track.update(i, x, extent, y, line))
    return np.array(rep)


def main(
    runs,
    ramps=(math.inf, 0.4),
    cache=None,
    n_frames: int = 40,
    variants=None,
    record_cache=None,
) -> list[dict]:
    """`runs`: (kind, name, seed, nuisance) with kind "condition" or "placement"; frames
    per run `n_frames` (the evidence: 40 for conditions, 48 for placements); `variants`:
    name → `JunctionTrack` overrides, each replayed per ramp value (default: none, the
    tracker's own); `record_cache`: a folder for the recorded runs (pickles; the replays
    of other variants then skip the tracker)."""
    variants = variants or {"": {}}
    from cslx.environment import configure

    configure()
    from cslx.sensor import default_sensor
    from experiments import tracking_generality as tg
    from experiments import tracking_sequences as ts

    rows, trackers = [], {}
    for kind, name, seed, nu in runs:
        key = f"{kind}_{name}_{nu}_{seed}_{n_frames}.pkl"
        path = None if record_cache is None else pathlib.Path(record_cache) / key
        if path is not None and path.exists():
            with open(path, "rb") as fh:
                run, seq, sensor, base, kalman, weld, x_ref = pickle.load(fh)
        else:
            rig = "default"
            if kind == "condition":
                seq = tg.sequence(seed, tg.CONDITIONS[name], n_frames, nu)
                sensor = seq.pop("sensor")
                rig = repr(tg.CONDITIONS[name].get("rig", {}))
            else:
                seq = ts.make_sequence(seed, nu, name, n_frames, cache)
                sensor = default_sensor()
            if rig not in trackers:  # one compiled tracker per rig
                trackers[rig] = recording_tracker(sensor)
            tracker = trackers[rig]
            run = record(tracker, seq)
            base = tg.score(run["obs"], seq, sensor)
            kalman, weld, x_ref = tracker.kalman, tracker.config.weld, tracker.x_ref
            seq = {k: v for k, v in seq.items() if k != "frames"}  # what `score` reads
            if path is not None:
                path.parent.mkdir(parents=True, exist_ok=True)
                with open(path, "wb") as fh:
                    pickle.dump((run, seq, sensor, base, kalman, weld, x_ref), fh)
        row = dict(run=f"{name} {nu} {seed}", tracker=(base["t_recall_pct"], base["t_false"]))
        for r in ramps:
            config = dataclasses.replace(weld, crossing_ramp_max=r)
            sights = sightings(run, config)
            first = None
            for name_v, kw in variants.items():
                rep = replay(run, sights, kalman, x_ref, **kw)
                first = rep if first is None else first
                obs = [dataclasses.replace(o) for o in run["obs"]]
                for o, x in zip(obs, rep, strict=True):
                    o.junction, o.junction_x_mm = bool(np.isfinite(x)), float(x)
                s = tg.score(obs, seq, sensor)
                row[f"ramp {r:g}{name_v}"] = (s["t_recall_pct"], s["t_false"])
                if rep is not first:  # frames whose report differs from the first variant's
                    row[f"ramp {r:g}{name_v}"] += (
                        int((~np.isclose(rep, first, 0, 0, True)).sum()),
                    )
        rows.append(row)
        print(" | ".join(f"{k} {v}" for k, v in row.items()), flush=True)
    for k in [k for k in rows[0] if k.startswith("ramp")] if rows else []:
        false = sum(row[k][1] for row in rows)
        low = sum(row[k][0] < 90.0 for row in rows)
        print(f"{k}: {false} false T frames, {low} runs with T recall < 90 %")
    return rows


if __name__ == "__main__":
    p = parser(__doc__.splitlines()[0], 40, 7400)
    p.add_argument("--seeds", type=int, default=1)
    p.add_argument("--condition", action="append", help="tracking_generality conditions")
    p.add_argument("--placement", action="append", help="tracking_sequences placements")
    p.add_argument("--nuisance", action="append")
    p.add_argument("--ramp", type=float, action="append", help="crossing_ramp_max values")
    p.add_argument("--cache", help="tracking_sequences frame cache")
    p.add_argument("--record-cache", help="folder for the recorded runs (pickles)")
    p.add_argument(
        "--variant",
        action="append",
        help="JunctionTrack overrides, e.g. bar_oblique_points=6,bar_oblique_deg=15 (repeatable;"
        " '-' the tracker's own)",
    )
    a = p.parse_args()
    seeds = range(a.seed, a.seed + a.seeds)
    nus = a.nuisance or ["clean"]
    todo = [("condition", c, s, n) for c in a.condition or [] for s in seeds for n in nus]
    todo += [("placement", q, s, n) for q in a.placement or [] for s in seeds for n in nus]
    cache = pathlib.Path(a.cache) if a.cache else None
    todo = todo or [("condition", "cross_toe", a.seed, "clean")]
    ramps = tuple(a.ramp or (math.inf, 0.4))
    variants = {f" [{v}]": parse_overrides(v) for v in a.variant or ["-"]}
    main(todo, ramps, cache, 4 if a.quick else a.frames, variants, a.record_cache)
