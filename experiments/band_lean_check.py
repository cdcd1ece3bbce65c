"""Band centres against full-frame centres on leaning stripes (issues 12 / 13, `band_lean`).

For each condition of `experiments.tracking_generality` (a rig; the projector rolled by
8 / 15 / 25° makes the stripes lean) one approach is rendered; frame k is processed on the
full frame (``roi=False``, the tracker's pipeline `tracking_config`) and in the bands that
frame k − 1 chose (`cslx.runtime.band_lean.next_bands`), and the two sets of centres are
compared where both are valid: per stripe the median / 99th percentile / max of
|band − full| in px, the share of full-frame centres the band also found, and how many
frames ran straight / sheared bands. Variants: ``interp`` (the sheared band, interpolated
between rows: the default), ``whole`` (the start rounded down to whole rows, a staircase
of integer offsets), ``off`` (``roi_lean=False``: straight bands only).

Run with ``python -m experiments.band_lean_check --seed 7800 --frames 12 [--condition …]``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from experiments.common import parser


def _compare(a, b):
    both = np.asarray(a.valid) & np.asarray(b.valid)
    d = np.abs(np.asarray(a.pos) - np.asarray(b.pos))[both]
    return d, both.sum() / max(int(np.asarray(b.valid).sum()), 1)


def run(conditions, seed: int, n_frames: int, variants=("interp", "whole", "off")):
    from cslx.environment import configure

    configure()
    import jax
    import jax.numpy as jnp

    from cslx.runtime import band_lean
    from cslx.runtime.pipeline import init_state, process_frame
    from cslx.runtime.tracker import tracking_config
    from experiments.tracking_generality import CONDITIONS, sequence

    starts = band_lean.lean_starts
    for name in conditions:
        seq = sequence(seed, CONDITIONS[name], n_frames, "clean")
        frames = [jnp.asarray(f) for f in seq["frames"]]
        for variant in variants:
            # a new sensor object per variant: `process_frame` traces its program anew
            sensor = jax.tree_util.tree_map(
                lambda x: jnp.asarray(x, jnp.float32) if isinstance(x, jax.Array) else x,
                seq["sensor"],
            )
            config = tracking_config()
            if variant == "off":
                config = dataclasses.replace(config, roi_lean=False)
            whole = variant == "whole"
            band_lean.lean_starts = (lambda *a: jnp.floor(starts(*a))) if whole else starts
            state = init_state(config, sensor.camera.image_size)
            diffs = {"h": [], "v": []}
            share = {"h": [], "v": []}
            kinds = {"full": 0, "straight": 0, "sheared": 0}
            for k, rgb in enumerate(frames):
                full, _ = process_frame(sensor, config, rgb, state, roi=False)
                sheared = bool(np.any(np.asarray(state.lean_h)[1:] != 0)) or bool(
                    np.any(np.asarray(state.lean_v)[1:] != 0)
                )
                res, state = process_frame(sensor, config, rgb, state)
                if k == 0 or not bool(res.used_roi):
                    kinds["full"] += 1
                    continue
                kinds["sheared" if sheared else "straight"] += 1
                for s, a, b in (
                    ("h", res.centres_h, full.centres_h),
                    ("v", res.centres_v, full.centres_v),
                ):
                    d, f = _compare(a, b)
                    diffs[s].append(d)
                    share[s].append(f)
            parts = [f"{name} {variant}: frames {kinds}"]
            for s in ("h", "v"):
                if diffs[s]:
                    d = np.concatenate(diffs[s])
                    parts.append(
                        f"{s} |band-full| median {np.median(d):.4f} p99 {np.percentile(d, 99):.4f}"
                        f" max {d.max():.4f} px, found {100 * np.mean(share[s]):.1f} %"
                    )
            print("; ".join(parts), flush=True)
    band_lean.lean_starts = starts


if __name__ == "__main__":
    p = parser(__doc__.splitlines()[0], 12, 7800)
    p.add_argument("--condition", action="append")
    p.add_argument("--variant", action="append")
    a = p.parse_args()
    conds = tuple(a.condition or ("base", "proj_roll_8", "proj_roll_15", "proj_roll_25"))
    run(conds, a.seed, a.frames, tuple(a.variant or ("interp", "whole", "off")))
