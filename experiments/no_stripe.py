"""No stripe in view (issue 11, item 7): what the linked detector reports with the laser off.

Every condition of the robust-extraction benchmark (`experiments.robust_extraction`: the four
presets and the five hard conditions, straight and T-junction scenes, 18 in all) is rendered
at the development seeds 7100 + condition index (NOT the held-out 9100–9117), frames
0..`--frames`−1, twice: as rendered (laser on) and with `laser_power` 0 (laser off; the same
scene, sun, glints and noise seed). Both stripes go through `cslx.segmentation.extract`
(method "linked"). Per stripe the script records the summary statistics a "no stripe"
decision could use: centres reported, share of the columns (rows) found, the median predicted
σ of the centres (`sigma_px` of the centre CSV), the median ridge strength (`strength`, in
units of the frame's ridge noise), the number of path pieces and the longest piece. Synthetic
frames with no laser at all are added: black, white (250), fully clipped (255), uniform grey,
Gaussian and uniform noise, a sunlit printed target and a sunlit red rust texture (both
rendered with the laser off).

With ``--dump FILE`` the laser-on centres (pos, valid, sigma, saturated, strength) of every
frame — these conditions plus the Table 6 frames (`common.round_robin`, seed `--table6-seed`)
and flat-wall frames (`experiments.flat_wall.render_flat`, development seeds 41–46) — are
saved to an .npz; ``--compare FILE`` checks the current code's output against such a dump
bit for bit (the gate must not move any result).

Writes `no_stripe.csv` / `no_stripe.md` to `--out` (default: a temporary directory, not
results/).
"""

from __future__ import annotations

import os
import time

import numpy as np

from experiments import common as C

FIELDS = [
    "condition",
    "frame",
    "laser",
    "stripe",
    "n",
    "found_share",
    "median_sigma_px",
    "p90_sigma_px",
    "median_strength",
    "pieces",
    "longest",
    "n_after_gate",
]


def conditions() -> list[tuple[str, str]]:
    from experiments.robust_extraction import conditions as conds

    return conds()


def laser_off(nuisance):
    """The `Nuisance` of a preset / hard condition with the laser switched off."""
    from cslx import sim

    return {**sim.NUISANCES, **sim.HARD_NUISANCES}[nuisance]._replace(laser_power=0.0)


def stripe_stats(c) -> dict:
    """Summary statistics of one stripe's `Centres` (linked)."""
    valid = np.asarray(c.valid, bool)
    sig = np.asarray(c.sigma, float)[valid]
    strength = np.asarray(c.strength, float)[valid]
    edges = np.diff(np.concatenate([[0], valid.astype(int), [0]]))
    starts, ends = np.flatnonzero(edges == 1), np.flatnonzero(edges == -1)
    lengths = ends - starts
    n = int(valid.sum())
    nan = float("nan")
    return dict(
        n=n,
        found_share=n / len(valid),
        median_sigma_px=float(np.median(sig)) if n else nan,
        p90_sigma_px=float(np.percentile(sig, 90)) if n else nan,
        median_strength=float(np.median(strength)) if n else nan,
        pieces=len(lengths),
        longest=int(lengths.max()) if len(lengths) else 0,
    )


def synthetic_frames(sensor, seed: int = 7190) -> dict[str, np.ndarray]:
    """Frames with no laser at all (seeded)."""
    from cslx import sim

    rng = np.random.default_rng(seed)
    shape = (480, 640, 3)
    out = {
        "black": np.zeros(shape, np.uint8),
        "white": np.full(shape, 250, np.uint8),
        "clipped": np.full(shape, 255, np.uint8),
        "grey": np.full(shape, 128, np.uint8),
        "noise_gauss": np.clip(rng.normal(128, 12, shape), 0, 255).astype(np.uint8),
        "noise_uniform": rng.integers(0, 256, shape).astype(np.uint8),
        "noise_grey": np.repeat(
            np.clip(rng.normal(100, 20, shape[:2]), 0, 255).astype(np.uint8)[..., None], 3, -1
        ),
    }
    sunny = sim.NUISANCES["sunny"]
    for i, kind in enumerate(("straight", "cross")):
        r = np.random.default_rng([seed, i])
        world = sim.random_world(kind, r)
        pose = sim.random_pose(world, kind, r, sensor)
        nz = sunny._replace(printed=1.0, laser_power=0.0)
        out[f"printed_sunny_{kind}"] = sim.render_image(sensor, world, pose, nz, seed=seed + i)
        # red rust: blotchy reddish albedo over a sunlit plate with the laser off
        off = sunny._replace(laser_power=0.0)
        plate = sim.render_image(sensor, world, pose, off, seed=seed + i)
        field = _blotches(r, shape[:2], 8.0)
        tint = np.stack([1.0 + 0.6 * field, 1.0 - 0.2 * field, 1.0 - 0.4 * field], -1)
        out[f"rust_sunny_{kind}"] = np.clip(plate * tint, 0, 255).astype(np.uint8)
    return out


def _blotches(rng, shape, grain_px: float) -> np.ndarray:
    """A smooth random field in [0, 1] (Gaussian-filtered noise, grain `grain_px`)."""
    from scipy.ndimage import gaussian_filter

    f = gaussian_filter(rng.normal(size=shape), grain_px)
    f = (f - f.min()) / (np.ptp(f) + 1e-12)
    return f


def _extract(image, stripe):
    from cslx import segmentation as seg

    return seg.extract(image, "linked", stripe=stripe)


def _ungated(image, stripe):
    """(centres without the no-stripe test, the number of centres the test lets through)."""
    from cslx.segmentation import presence

    limit = presence.NO_STRIPE_SIGMA
    presence.NO_STRIPE_SIGMA = None
    try:
        c = _extract(image, stripe)
    finally:
        presence.NO_STRIPE_SIGMA = limit
    if limit is None:
        return c, int(np.asarray(c.valid).sum())
    gated = presence.absent(c.pos, c.valid, c.sigma, c.strength, c.saturated)
    return c, int(np.asarray(gated[1]).sum())


def _arrays(c) -> dict[str, np.ndarray]:
    return {
        "pos": np.asarray(c.pos),
        "valid": np.asarray(c.valid),
        "sigma": np.asarray(c.sigma),
        "saturated": np.asarray(c.saturated),
        "strength": np.asarray(c.strength),
    }


def laser_on_frames(frames: int, seed: int, table6_seed: int, table6_frames: int, sensor):
    """(name, image) of every laser-on frame the gate must leave alone."""
    from experiments.flat_wall import NUISANCES as FLAT
    from experiments.flat_wall import render_flat

    for c, (kind, nuisance) in enumerate(conditions()):
        for i in range(frames):
            yield (
                f"robust/{kind}/{nuisance}/{seed + c}/{i}",
                C.frame_at(kind, nuisance, seed + c, i, sensor)[0],
            )
    for f, (kind, nuisance, s, image, _) in enumerate(
        C.round_robin(table6_frames, table6_seed, sensor)
    ):
        yield f"table6/{kind}/{nuisance}/{s}/{f}", image
    for nuisance in FLAT:
        for s in range(41, 47):
            yield f"flat/{nuisance}/{s}", render_flat(nuisance, s, sensor)[0]


def dump_or_compare(path: str, compare: bool, frames, seed, table6_seed, table6_frames) -> dict:
    """Save (or compare against) the laser-on centres of every frame; returns counts."""
    from cslx.sensor import default_sensor

    sensor = default_sensor()
    ref = dict(np.load(path)) if compare else {}
    out: dict[str, np.ndarray] = {}
    counts = dict(frames=0, stripes=0, identical=0, centres=0, differ=[])
    for name, image in laser_on_frames(frames, seed, table6_seed, table6_frames, sensor):
        counts["frames"] += 1
        for stripe in ("h", "v"):
            a = _arrays(_extract(image, stripe))
            counts["stripes"] += 1
            counts["centres"] += int(a["valid"].sum())
            same = True
            for k, v in a.items():
                key = f"{name}|{stripe}|{k}"
                if compare:
                    same &= np.array_equal(ref[key], v, equal_nan=True)
                else:
                    out[key] = v
            if compare:
                counts["identical"] += int(same)
                if not same:
                    counts["differ"].append(f"{name}|{stripe}")
    if not compare:
        np.savez_compressed(path, **out)
    print(counts)
    return counts


def time_test(calls: int = 200) -> dict:
    """Warm wall time (µs, median) of the no-stripe test on one 640-column stripe."""
    import jax

    from cslx.segmentation import presence

    rng = np.random.default_rng(0)
    n = 640
    arrays = (
        rng.normal(200, 1, n),
        np.ones(n, bool),
        np.full(n, 0.08),
        np.full(n, 60.0),
        np.zeros(n, bool),
    )

    def run(a):
        return jax.block_until_ready(presence.absent(*a))

    r = C.timeit(run, [arrays], calls, budget_s=10.0, warmup=5)
    return dict(median_us=1e3 * r["time_ms"], p90_us=1e3 * r["p90_ms"], load=C.load_average())


def main(frames: int = 2, seed: int = 7100, out: str | None = None) -> list[dict]:
    """Laser on / off statistics per condition and stripe; the synthetic frames."""
    import tempfile

    from cslx.provenance import provenance, provenance_md, write_csv
    from cslx.sensor import default_sensor

    out = out or tempfile.mkdtemp(prefix="no_stripe_")
    sensor = default_sensor()
    load_start = C.load_average()
    rows = []
    t0 = time.time()
    for c, (kind, nuisance) in enumerate(conditions()):
        for i in range(frames):
            on, _ = C.frame_at(kind, nuisance, seed + c, i, sensor)
            off, _ = C.frame_at(kind, laser_off(nuisance), seed + c, i, sensor)
            for laser, image in (("on", on), ("off", off)):
                for stripe in ("h", "v"):
                    cen, after = _ungated(image, stripe)
                    rows.append(
                        dict(
                            condition=f"{kind}/{nuisance}",
                            frame=i,
                            laser=laser,
                            stripe=stripe,
                            **stripe_stats(cen),
                            n_after_gate=after,
                        )
                    )
        print(f"{kind}/{nuisance}: {time.time() - t0:.0f} s", flush=True)
    for name, image in synthetic_frames(sensor).items():
        for stripe in ("h", "v"):
            cen, after = _ungated(image, stripe)
            rows.append(
                dict(
                    condition=f"synthetic/{name}",
                    frame=0,
                    laser="none",
                    stripe=stripe,
                    **stripe_stats(cen),
                    n_after_gate=after,
                )
            )
    os.makedirs(out, exist_ok=True)
    write_csv(os.path.join(out, "no_stripe.csv"), rows, FIELDS)
    prov = provenance(dict(frames=frames, seed=seed))
    with open(os.path.join(out, "no_stripe.md"), "w", encoding="utf-8") as f:
        f.write(_markdown(rows, frames, seed, load_start) + "\n" + provenance_md(prov) + "\n")
    print(f"wrote {out}/no_stripe.{{csv,md}}")
    return rows


def _fmt(x) -> str:
    return "—" if not np.isfinite(x) else f"{x:.3f}"


def _markdown(rows, frames, seed, load_start) -> str:
    out = [
        "# No stripe in view: the linked detector with the laser off",
        "",
        f"{frames} frame(s) per condition, development seeds {seed}–{seed + 17}; load "
        f"{load_start} → {C.load_average()}. Laser off: the same frame with `laser_power` 0. "
        "`n` is what the detector's statistics saw; `after` what it reports (the gate applied).",
        "",
        "| condition | frame | laser | stripe | n | after | found | med σ px | p90 σ px | "
        "med z | pieces | longest |",
        "|---|---:|---|---|---:|---:|---:|---:|---:|---:|---:|---:|",
    ]
    for r in rows:
        out.append(
            f"| {r['condition']} | {r['frame']} | {r['laser']} | {r['stripe']} | {r['n']} | "
            f"{r['n_after_gate']} | {_fmt(r['found_share'])} | {_fmt(r['median_sigma_px'])} | "
            f"{_fmt(r['p90_sigma_px'])} | {_fmt(r['median_strength'])} | {r['pieces']} | "
            f"{r['longest']} |"
        )
    return "\n".join(out)


if __name__ == "__main__":
    a = C.parser(__doc__, 2, 7100)
    a.set_defaults(out=None)
    a.add_argument("--dump", help="save the laser-on centres of every frame to this .npz")
    a.add_argument("--compare", help="compare the laser-on centres with this .npz")
    a.add_argument("--table6-seed", type=int, default=6)
    a.add_argument("--table6-frames", type=int, default=16)
    a.add_argument("--time", action="store_true", help="time the no-stripe test alone")
    args = a.parse_args()
    if args.time:
        print(time_test())
    elif args.dump or args.compare:
        dump_or_compare(
            args.dump or args.compare,
            bool(args.compare),
            args.frames,
            args.seed,
            args.table6_seed,
            args.table6_frames,
        )
    else:
        main(1 if args.quick else args.frames, args.seed, args.out)
