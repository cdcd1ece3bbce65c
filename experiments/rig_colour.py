"""Laser-colour audit of the tracker's colour weights (`cslx.runtime.stripe_colour`).

Renders T scenes (`cslx.sim.random_world("cross")`, clean and sunny by seed parity, as
`experiments.rig_sigma`) with a red, green or blue laser (`cslx.sim.render.LASER_RGB`), lets
a `cslx.runtime.tracker.Tracker` choose (σ, weights) on the first frame, and runs the
tracker's pipeline (`cslx.runtime.pipeline.process_frame`, `tracking_config`) with the
weights before (the configured R − G, σ from its widths: ``auto_weights=False``) and after
(the tracker's choice) on a cold and a tracking frame. Prints per stripe and frame the
gross centres (> 1 mm from the truth in 3-D) and the median error, then a summary per
laser; writes nothing.

    python -m experiments.rig_colour --lasers green --seeds 8800 8801
"""

from __future__ import annotations

import argparse
import dataclasses

import numpy as np

from experiments.rig_sigma import errors


def frames_for(laser: str, seed: int, n: int = 2):
    from cslx.sensor import default_sensor
    from cslx.sim import NUISANCES, random_pose, random_world, render_frame
    from cslx.sim.render import LASER_RGB

    sensor = default_sensor()
    rng = np.random.default_rng(seed)
    world = random_world("cross", rng)
    pose = random_pose(world, "cross", rng, sensor)
    nz = NUISANCES["clean" if seed % 2 == 0 else "sunny"]._replace(laser_rgb=LASER_RGB[laser])
    return sensor, [
        render_frame(sensor, world, pose, nz, seed * 10 + i, scene_seed=seed) for i in range(n)
    ]


def audit(lasers, seeds, n_frames=2):
    import jax.numpy as jnp

    from cslx.runtime import pipeline as pl
    from cslx.runtime.stripe_width import with_frame_sigma
    from cslx.runtime.tracker import Tracker

    sensor, _ = frames_for("red", seeds[0], 1)
    trackers = {
        "before": Tracker(sensor, auto_weights=False, log=print),
        "after": Tracker(sensor, log=print),
    }
    rows = []
    for laser in lasers:
        for seed in seeds:
            _, frames = frames_for(laser, seed, n_frames)
            H, W = frames[0][0].shape[:2]
            for name, tr in trackers.items():
                tr.reset()
                tr.step(frames[0][0], odometry=0.0)
                config = with_frame_sigma(tr.config, tr.sigma, H, W)
                config = dataclasses.replace(config, weights=tuple(tr.weights))
                state = pl.init_state(config, (W, H), jnp.float32)
                for i, (img, gt) in enumerate(frames):
                    res, state = pl.process_frame(sensor, config, img, state)
                    for axis, c, key in ((0, res.centres_h, "h_xyz"), (1, res.centres_v, "v_xyz")):
                        e = errors(c, gt[key], sensor, axis)
                        r = dict(
                            laser=laser,
                            seed=seed,
                            frame=i,
                            run=name,
                            sigma=tr.sigma,
                            weights=tuple(tr.weights),
                            stripe="hv"[axis],
                            gross=int(np.sum(e > 1.0)),
                            median_mm=float(np.median(e)) if len(e) else np.nan,
                            n=len(e),
                        )
                        rows.append(r)
                        print(
                            f"{laser:5s} {seed} f{i} {name:6s} σ{r['sigma']:<4} w {r['weights']}"
                            f" {r['stripe']} gross {r['gross']:4d} med {r['median_mm']:.3f}"
                            f" n {r['n']:4d}",
                            flush=True,
                        )
    for laser in lasers:
        for name in trackers:
            for s in "hv":
                sel = [
                    r for r in rows if r["laser"] == laser and r["run"] == name and r["stripe"] == s
                ]
                g = [r["gross"] for r in sel]
                m = [r["median_mm"] for r in sel]
                print(
                    f"SUMMARY {laser} {name} {s}: gross {np.mean(g):.1f} ({min(g)}–{max(g)}),"
                    f" median {np.nanmedian(m):.3f} ({np.nanmin(m):.3f}–{np.nanmax(m):.3f}) mm,"
                    f" weights {sorted({r['weights'] for r in sel})}"
                )
    return rows


def main(argv=None):
    p = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    p.add_argument("--lasers", nargs="+", default=["red", "green", "blue"])
    p.add_argument("--seeds", nargs="+", type=int, default=[8800, 8801])
    p.add_argument("--frames", type=int, default=2)
    a = p.parse_args(argv)
    audit(a.lasers, a.seeds, a.frames)


if __name__ == "__main__":
    main()
