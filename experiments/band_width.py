"""How wide the tracking bands must be: stripe excursions, tracking share and scores per width.

The tracking bands (`PipelineConfig.roi_half_h` / ``roi_half_w``) are centred on the
previous frame's stripe (`cslx.runtime.band_lean.next_bands`); a stripe that comes closer
than ``roi_margin`` to a band edge ends tracking mode. On a rigid sensor the stripes move
in the image only with depth (bead height, wall distance, the bar of a T), so the band can
be as narrow as those excursions plus the margin. Per development approach to a T
(`experiments.tracking_sequences`'s scenes; both placements; the nuisances asked for) this
script prints:

- the excursion: over the frames after the first, the 98th percentile of |centre − the
  previous frame's median centre| (the share `next_bands` requires inside the band), px,
  its largest value over the frames, for each stripe (the default pipeline, MED in bands);
- per variant, the share of frames processed in the bands (``used_roi``) with
  `PipelineConfig()` changed by the variant, carried from frame to frame;
- per variant, the `Tracker`'s issue-12 scores (offset error mean / max mm, heading error
  mean °, T recall % / false T frames) with MED in the bands (``config=PipelineConfig(...)``)
  and with the tracker's own pipeline (`tracking_config` changed the same way), all in one
  process, the same frames in the same order;

then with ``--video SEED ...`` the band − full-frame MED agreement on rendered sunny video
(`experiments.band_alternate.agreement`: worst |median band − full| px over every third of
24 carried frames and both stripes, and median |centre − truth| px).

    python -m experiments.band_width --seeds 7301 7302 7305 \\
        --variant h24w48=roi_half_h:24,roi_half_w:48 --video 0 1 555
"""

from __future__ import annotations

import argparse
import dataclasses
import logging
import pathlib

import numpy as np

from experiments.band_alternate import carried


def parse_variant(text: str) -> tuple[str, dict]:
    name, spec = text.split("=", 1)
    return name, {k: int(v) for k, v in (p.split(":") for p in spec.split(","))}


def excursion(results) -> tuple[float, float, float, float]:
    """Largest over frames 1.. of the 98th-percentile |centre − previous frame's stripe|,
    px: (h, v) against the previous median (a straight band), then (h, v) against the
    previous frame's least-squares line through its centres, refitted once within 8 px
    (a sheared band, `cslx.runtime.band_lean`)."""
    straight, line = [], []
    for s in ("h", "v"):
        worst = [0.0, 0.0]
        for prev, cur in zip(results[:-1], results[1:], strict=True):
            cp, cc = getattr(prev, f"centres_{s}"), getattr(cur, f"centres_{s}")
            vp, vc = np.asarray(cp.valid), np.asarray(cc.valid)
            if vp.sum() < 10 or vc.sum() == 0:
                continue
            pp, pc = np.asarray(cp.pos, float), np.asarray(cc.pos, float)
            d = np.abs(pc[vc] - np.round(np.median(pp[vp])))
            worst[0] = max(worst[0], float(np.percentile(d, 98)))
            idx = np.arange(len(pp), dtype=float)
            fit = np.polyfit(idx[vp], pp[vp], 1)
            near = vp & (np.abs(pp - np.polyval(fit, idx)) <= 8.0)
            if near.sum() >= 10:
                fit = np.polyfit(idx[near], pp[near], 1)
            d = np.abs(pc[vc] - np.polyval(fit, idx[vc]))
            worst[1] = max(worst[1], float(np.percentile(d, 98)))
        straight.append(worst[0])
        line.append(worst[1])
    return straight[0], straight[1], line[0], line[1]


def main(argv=None) -> int:
    from cslx.environment import configure

    configure()
    import jax.numpy as jnp

    from cslx.runtime.pipeline import PipelineConfig
    from cslx.runtime.tracker import Tracker, tracking_config
    from cslx.sensor import default_sensor
    from experiments import tracking_sequences as ts
    from experiments.bench_speed import sensor32

    p = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    p.add_argument("--seeds", type=int, nargs="*", default=[7301, 7302, 7305])
    p.add_argument("--variant", action="append", default=[], help="name=field:int,...")
    p.add_argument("--nuisance", nargs="+", default=list(ts.NUISANCES))
    p.add_argument("--frames", type=int, default=48)
    p.add_argument("--cache", default="/tmp/cslx-tracking-sequences/sequences")
    p.add_argument("--video", type=int, nargs="*", default=[])
    a = p.parse_args(argv)
    forbidden = {7303, 7304, 7306, 7307}
    if forbidden & set(a.seeds):
        raise SystemExit("held-out sequence seeds")
    variants = {"base": {}} | dict(parse_variant(v) for v in a.variant)
    sensor32_ = sensor32()
    log = logging.getLogger("band_width")
    med = {k: PipelineConfig(**kw) for k, kw in variants.items()}
    own = {k: dataclasses.replace(tracking_config(), **kw) for k, kw in variants.items()}
    trackers = {
        (k, kind): Tracker(default_sensor(), config=c, log=log)
        for kind, cs in (("med", med), ("own", own))
        for k, c in cs.items()
    }
    scores = {key: [] for key in trackers}
    roi = {k: [] for k in variants}
    exc = []
    for seed in a.seeds:
        for placement in ts.PLACEMENTS:
            for nuisance in a.nuisance:
                seq = ts.make_sequence(seed, nuisance, placement, a.frames, pathlib.Path(a.cache))
                frames = [jnp.asarray(f) for f in seq["frames"]]
                text = []
                for k, c in med.items():
                    res = carried(sensor32_, c, frames)
                    share = float(np.mean([bool(r.used_roi) for r in res]))
                    roi[k].append(share)
                    if k == "base":
                        exc.append(excursion(res))
                        e = exc[-1]
                        text.append(f"excursion h {e[0]:.1f} v {e[1]:.1f}, line {e[2]:.1f} / "
                                    f"{e[3]:.1f} px")  # fmt: skip
                    text.append(f"{k} roi {share:.2f}")
                for key, t in trackers.items():
                    s = ts.score(ts.run_tracker(t, seq), seq)
                    scores[key].append(s)
                    text.append(
                        f"{key[0]}/{key[1]} {s['offset_mean_mm']:.3f}/{s['offset_max_mm']:.3f} "
                        f"{s['heading_mean_deg']:.3f}° T {s['t_recall_pct']:.0f}/{s['t_false']}"
                    )
                print(seed, placement, nuisance, " | ".join(text), flush=True)
    if exc:
        e = np.asarray(exc)
        for j, what in enumerate(("h", "v", "h from the line", "v from the line")):
            print(f"excursion over {len(e)} runs, {what}: max {e[:, j].max():.1f} px, "
                  f"median {np.median(e[:, j]):.1f} px")  # fmt: skip
    for k in variants:
        if roi[k]:
            print(f"{k}: roi share mean {np.mean(roi[k]):.3f}, min {np.min(roi[k]):.3f}")
    for key, rows in scores.items():
        if not rows:
            continue
        off = np.mean([r["offset_mean_mm"] for r in rows])
        mx = np.mean([r["offset_max_mm"] for r in rows])
        hd = np.mean([r["heading_mean_deg"] for r in rows])
        rec = np.mean([r["t_recall_pct"] for r in rows])
        false = int(np.sum([r["t_false"] for r in rows]))
        print(f"{key[0]}/{key[1]}: {len(rows)} runs, offset mean {off:.4f} mm, max mean "
              f"{mx:.3f} mm, heading {hd:.3f}°, T recall {rec:.1f} %, false T {false}")  # fmt: skip
    if a.video:
        from experiments.band_alternate import agreement
        from experiments.bench_speed import video_frames

        for seed in a.video:
            frames, truth = video_frames(24, seed, with_truth=True)
            for k, c in med.items():
                res = carried(sensor32_, c, frames)
                worst, err = agreement(sensor32_, c, res, frames, truth)
                share = float(np.mean([bool(r.used_roi) for r in res]))
                e = excursion(res)
                print(f"video {seed} {k}: worst |median band − full| {worst:.4f} px, median "
                      f"|centre − truth| {err:.4f} px, roi {share:.2f}, excursion h {e[0]:.1f} "
                      f"v {e[1]:.1f}, line {e[2]:.1f} / {e[3]:.1f} px", flush=True)  # fmt: skip
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
