"""Where the linked detector's p95 is (issue 11): per-centre errors by region and condition.

Renders the development frames of `experiments.robust_extraction` (seed 7100 + condition,
frames 0 … `--frames` − 1; cached as .npz under `--cache`), runs `cslx extract`'s default
(`linked`) on both stripes, and keeps every centre's signed pixel error along the search axis
(estimate − ground truth), its 3-D error (mm, `stripe_point_errors`) and its region by the
ground truth's own path:

- ``toe``: within `TOE_REACH` centres of a bend (|t[j+5] − 2 t[j] + t[j−5]| > 0.1 px);
- ``cap``: not a toe, > 0.3 px off a robust quadratic through the whole true path (the bead);
- ``near``: within `NEAR` centres of a bend, neither of the above (the plates by the bead);
- ``cross``: within 12 centres of the other stripe; ``border``: within 12 of the path's ends;
- ``plate``: the rest (the plates far from the bead).

`--set module.NAME=value` overrides a constant of `cslx.segmentation` before the first call
(a variant); `--half a|b` keeps one half of the conditions (`HALVES`: every nuisance once per
half, the scene kinds alternating), for tuning on one half and confirming on the other.
Writes the per-centre arrays to `--out` (.npz) and prints the pooled figures and the
breakdown.
"""

from __future__ import annotations

import argparse
import importlib
import os

import numpy as np

from experiments import common as C

TOE_REACH = 10
NEAR = 40
#: Condition indices of each half: nuisance k's straight scene in half a for even k, its
#: cross scene for odd k (and the other one in half b).
HALVES = {
    "a": tuple(2 * k + (k % 2) for k in range(9)),
    "b": tuple(2 * k + 1 - (k % 2) for k in range(9)),
}
REGIONS = ("plate", "near", "toe", "cap", "cross", "border")


def regions(t: np.ndarray, other: np.ndarray | None) -> np.ndarray:
    """Region code (index into `REGIONS`) of every column of the true path t (module doc)."""
    n = len(t)
    ok = np.isfinite(t)
    code = np.zeros(n, int)
    j = np.arange(n)
    d2 = np.full(n, np.nan)
    d2[5:-5] = t[10:] - 2 * t[5:-5] + t[:-10]
    bend = np.abs(np.nan_to_num(d2)) > 0.1
    dist = np.full(n, np.inf)
    if bend.any():
        b = j[bend]
        dist = np.min(np.abs(j[:, None] - b[None, :]), axis=1)
    x = j[ok].astype(float)
    y = t[ok]
    keep = np.ones(len(x), bool)
    for _ in range(6):
        if keep.sum() < 10:
            break
        coef = np.polyfit(x[keep], y[keep], 2)
        r = np.abs(y - np.polyval(coef, x))
        keep = r < max(0.3, 3 * np.median(r[keep]))
    dev = np.zeros(n)
    if len(x) >= 10:
        dev[ok] = np.abs(y - np.polyval(coef, x))
    code[(dist > TOE_REACH) & (dev > 0.3)] = 3
    code[(dist <= NEAR) & (code == 0)] = 1
    code[dist <= TOE_REACH] = 2
    if other is not None:
        # the other stripe crosses where its position (in this stripe's index) meets j
        rows = np.clip(np.round(np.nan_to_num(t)).astype(int), 0, len(other) - 1)
        cross = np.abs(other[rows] - j) < 1.0
        if cross.any():
            c = j[cross & ok]
            if len(c):
                code[np.min(np.abs(j[:, None] - c[None, :]), axis=1) <= 12] = 4
    idx = j[ok]
    if len(idx):
        code[(j - idx.min() < 12) | (idx.max() - j < 12)] = 5
    return code


def frame(c: int, i: int, cache: str):
    """(image, gt) of condition c's frame i, rendered once and cached."""
    path = os.path.join(cache, f"{c}_{i}.npz")
    if os.path.exists(path):
        z = np.load(path)
        return z["image"], {k: z[k] for k in ("h_v", "h_xyz", "v_u", "v_xyz")}
    from cslx.sensor import default_sensor
    from experiments.robust_extraction import conditions

    kind, nuisance = conditions()[c]
    image, gt = C.frame_at(kind, nuisance, 7100 + c, i, default_sensor())
    os.makedirs(cache, exist_ok=True)
    np.savez(path, image=image, **{k: gt[k] for k in ("h_v", "h_xyz", "v_u", "v_xyz")})
    return image, gt


def apply_sets(sets):
    for s in sets:
        name, value = s.split("=", 1)
        mod, attr = name.rsplit(".", 1)
        m = importlib.import_module(f"cslx.segmentation.{mod}")
        setattr(m, attr, type(getattr(m, attr))(eval(value)))


def run(conds, frames, cache):
    from cslx import segmentation as seg
    from cslx.sensor import default_sensor

    sensor = default_sensor()
    rows = []
    for c in conds:
        for i in range(frames):
            image, gt = frame(c, i, cache)
            for stripe in ("h", "v"):
                t = gt["h_v"] if stripe == "h" else gt["v_u"]
                other = gt["v_u"] if stripe == "h" else gt["h_v"]
                uv = seg.centres_to_pixels(seg.extract(image, "linked", stripe=stripe), stripe)
                pos = uv[:, 1] if stripe == "h" else uv[:, 0]
                xyz = gt[C.STRIPE_GT[stripe]]
                err, _, _, _ = C.point_errors(uv, xyz, sensor, C.STRIPE_PLANE[stripe])
                m = np.all(np.isfinite(uv), 1) & np.all(np.isfinite(xyz), 1)
                e = np.full(len(pos), np.nan)
                e[m] = err
                rows.append(dict(c=c, i=i, s=stripe, t=t, pos=pos, mm=e, region=regions(t, other)))
    return rows


def summary(rows, label=""):
    from experiments.robust_extraction import conditions

    names = [n for _, n in conditions()]
    out = {}
    for s in ("h", "v"):
        rs = [r for r in rows if r["s"] == s]
        mm = np.concatenate([r["mm"] for r in rs])
        ngt = sum(int(np.isfinite(r["t"]).sum()) for r in rs)
        e = mm[np.isfinite(mm)]
        out[s] = (len(e) / ngt, int((e > 1).sum()), np.median(e), np.percentile(e, 95))
        print(f"{label} {s.upper()}: detection {100 * out[s][0]:.3f} %, gross {out[s][1]}, "
              f"median {out[s][2]:.4f}, p95 {out[s][3]:.4f} mm ({len(e)} centres)")  # fmt: skip
        for n in dict.fromkeys(names[r["c"]] for r in rs):
            ee = np.concatenate([r["mm"] for r in rs if names[r["c"]] == n])
            ee = ee[np.isfinite(ee)]
            print(f"   {n:16s} {np.median(ee):.4f} {np.percentile(ee, 95):.4f} {(ee > 1).sum()}")
    return out


def breakdown(rows):
    """Share of centres and of the errors above the pooled p95 by region; plate bias/noise."""
    for s in ("h", "v"):
        rs = [r for r in rows if r["s"] == s]
        mm = np.concatenate([r["mm"] for r in rs])
        reg = np.concatenate([r["region"] for r in rs])
        sgn = np.concatenate([r["pos"] - r["t"] for r in rs])
        ok = np.isfinite(mm)
        p95 = np.percentile(mm[ok], 95)
        tail = ok & (mm > p95)
        print(f"{s.upper()} pooled p95 {p95:.4f} mm")
        for k, name in enumerate(REGIONS):
            q = ok & (reg == k)
            if not q.any():
                continue
            print(f"  {name:7s} centres {100 * q.sum() / ok.sum():5.1f} %  median "
                  f"{np.median(mm[q]):.4f} p95 {np.percentile(mm[q], 95):.4f} mm  tail share "
                  f"{100 * (tail & q).sum() / tail.sum():5.1f} %  signed px mean "
                  f"{np.mean(sgn[q]):+.4f} rms {np.sqrt(np.mean(sgn[q] ** 2)):.4f}")  # fmt: skip


def plate_structure(rows):
    """Plate centres: per-condition bias, the RMS kept by running means, autocorrelation."""
    from experiments.robust_extraction import conditions

    names = [n for _, n in conditions()]
    for s in ("h", "v"):
        print(f"{s.upper()} plate (far from the bead): per condition mean / rms signed px")
        per = {}
        ac = {lag: [] for lag in (1, 3, 10, 30, 100)}
        keep = {w: [] for w in (5, 21, 61, 201)}
        for r in rows:
            if r["s"] != s:
                continue
            e = r["pos"] - r["t"]
            q = (r["region"] == 0) & np.isfinite(e)
            per.setdefault(names[r["c"]], []).append(e[q])
            # contiguous runs of plate centres, ≥ 100 long
            idx = np.flatnonzero(q)
            if not len(idx):
                continue
            cuts = np.flatnonzero(np.diff(idx) > 1) + 1
            for run in np.split(idx, cuts):
                if len(run) < 100:
                    continue
                x = e[run] - np.mean(e[run])
                v = np.mean(x**2)
                for lag in ac:
                    if lag < len(x) - 10:
                        ac[lag].append(np.mean(x[:-lag] * x[lag:]) / v)
                for w in keep:
                    if w < len(x):
                        rm = np.convolve(e[run], np.ones(w) / w, mode="valid")
                        keep[w].append(np.sqrt(np.mean(rm**2) / np.mean(e[run] ** 2)))
        for n, es in per.items():
            x = np.concatenate(es)
            fr = [np.mean(v) for v in es if len(v)]
            print(f"   {n:16s} mean {np.mean(x):+.4f} rms {np.sqrt(np.mean(x**2)):.4f} "
                  f"per-frame means {' '.join(f'{m:+.3f}' for m in fr)}")  # fmt: skip
        print("   autocorrelation (median over runs): " + ", ".join(
            f"lag {k}: {np.median(v):.2f}" for k, v in ac.items() if v))  # fmt: skip
        print("   RMS kept by a running mean (median): " + ", ".join(
            f"{k}: {np.median(v):.2f}" for k, v in keep.items() if v))  # fmt: skip


def main():
    a = argparse.ArgumentParser(description=__doc__)
    a.add_argument("--frames", type=int, default=3)
    a.add_argument("--half", choices=("a", "b", "all"), default="all")
    a.add_argument("--cache", default="/tmp/ext11g/frames")
    a.add_argument("--out", default="")
    a.add_argument("--set", action="append", default=[])
    a.add_argument("--analyse", action="store_true", help="breakdown and plate structure")
    a.add_argument("--raw", action="store_true", help="the second pass without its smoothing")
    args = a.parse_args()
    apply_sets(args.set)
    if args.raw:
        from cslx.segmentation import refine

        refine.LOCAL_WEIGHTS = False
        refine.smooth_path = lambda new, valid, *a, **k: (new, None)
    conds = range(18) if args.half == "all" else HALVES[args.half]
    rows = run(conds, args.frames, args.cache)
    summary(rows, " ".join(args.set) or "default")
    if args.analyse:
        breakdown(rows)
        plate_structure(rows)
    if args.out:
        np.save(args.out, np.array(rows, dtype=object), allow_pickle=True)


if __name__ == "__main__":
    main()
