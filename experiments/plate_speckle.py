"""The plates' speckle floor of the linked detector (issue 11, the p95): how the error on the
plates is correlated along the stripe, and what a longer along-path average could take off.

For the development frames of `experiments.tail_structure` (seeds 7100 + condition, frames
0 … `--frames` − 1, cached), both stripes, the default `linked` detector runs once; its second
pass is intercepted (as in `experiments.toe_leak`) to re-measure the same columns at every
stage, each signed pixel error along the search axis (estimate − ground truth):

- ``raw``: each column's own centre (`refine.refine_centres`, no along-path average);
- ``fit``: each column's own speckle-weighted profile fit (`profile.fit_centres`);
- ``re6``: the re-measurement averaged along the path (σ `refine.SIGMA_REFINE`);
- ``final``: the detector's output (profile fit / blend, the final ICI smoothing).

(1) Plates (`tail_structure.regions` code 0: far from the bead, the crossing and the ends),
contiguous runs of ≥ `MIN_RUN` centres: the error's autocorrelation by lag (median over runs,
each run's own mean removed, and the share of the error's mean square that is the run's mean:
an offset no average along the run removes), the correlation length (the lag at which it
falls below 1/e), and per condition the RMS (px) and p95 (mm).

(2) The error against an extra centred local-line average along the path, ±L centres, on the
``raw`` and ``final`` centres: (a) blind, over every valid centre (what a longer window does at
the toes and caps too), (b) oracle, within each plate run only (the true path's regions: what
a perfect kink detector would allow). 3-D errors are recomputed (`stripe_point_errors`), p95
(mm) per region. White noise would fall as 1 / √(2L + 1). (2b) One polynomial (degree 1 / 2)
through each whole straight segment of the final centres, the segments from the true
regions (oracle) or from the estimated path's own kinks (`straight`): the longest average
an adaptive window could use.

(3) `--ablate`: the same frames rendered again with parts of the image formation off.

Findings (issue 11; development seeds 7100–7117, frames 0–2, 54 frames, H / V; `--frames 3`):

- Where the pooled p95 (0.1285 / 0.1342 mm; 7.8 / 9.9 % of the centres above 0.1 mm) is:
  the plates far from the bead (`regions` 0, 68 / 74 % of the centres) have p95 0.078 /
  0.093 mm — H already within the goal, V 0.093 — and hold 22 / 30 % of the centres above
  0.1 mm; the toes 0.286 / 0.300 (46 / 29 %), the caps 0.175 / 0.317 (15 / 13 %), the plates
  within 40 centres of a bend 0.099 / 0.147, the crossing 0.222 / 0.145, the ends 0.128 /
  0.217. With the far plates' error set to 0 the pooled p95 would be 0.114 / 0.120 mm: the
  plates' speckle is not what keeps the p95 above 0.1 mm (the toes alone: 0.093 / 0.112).
- Each column's own centre (``raw``) has white error: autocorrelation at lag 1 / 2 / 3
  0.54 / 0.13 / 0.00 (H), 0.52 / 0.14 / 0.02 (V), correlation length 1.4 centres (the
  speckle grain is 1.2 px), no offset per run; RMS 0.17–0.29 px per condition (saturated
  cores 0.17–0.19, printed target 0.38–0.52). The profile fit's per-column error is whiter
  still (length 0.9) and smaller on clean and glare frames (0.17–0.19 px), larger where the
  tip is clipped (0.26–0.72). The ``final`` error is long-correlated (length 22 / 27 centres;
  the run's own mean holds 17 / 30 % of its mean square) because it is already an average
  over windows up to whole plates: its RMS on the plates, 0.040 / 0.038 px, is what a line
  through each whole plate run of the raw centres gives (0.043 px H), i.e. the √N limit of
  the plates' lengths (runs of 181 / 186 centres, centre-weighted median; a line through n
  centres of RMS 0.27 px and variance factor 1 + 2 Σ ρ = 2.36 averages to 0.27 √(2 · 2.36 /
  n) = 0.044 px at n = 180). White-noise arithmetic: p95 0.08 mm asks for ≈ 100 (H) / 140 (V)
  independent-equivalent centres averaged at every centre (a line's value at its end needs
  four times as many), more than a plate between a toe and the border offers at its ends.
- Longer windows: on the plates only (oracle), an extra line ±256 takes H plates 0.078 →
  0.067 mm (pooled 0.127 → 0.118); V plates, curved by the lens distortion, get worse beyond
  ±16 (0.093 → 0.088 at ±16, 0.135 at ±64). One polynomial through each whole true plate
  segment: H 0.069 (line), pooled 0.118; V 0.086 (quadratic), pooled 0.130. With the segments
  from the estimated path's kinks (second difference at lag 5 > 0.03–0.08 px, ±20–30 centres
  kept out) instead: H pooled 0.1274 → 0.1272–0.1274, V 0.1342 → 0.1336–0.1346 — nothing.
  Blind (everywhere, no kink test) longer windows round the toes: ±16: toes 0.282 → 0.480 /
  0.300 → 0.537 mm; ±32: gross 4 → 151 / 11 → 94 centres. The second pass's ICI smoothing
  (`path.smooth_path`, one-sided windows and lines to ±256) is already the adaptive window
  (long on straight plates, short at kinks); its upper bound with a perfect kink detector is
  −7 % (H) / −3 % (V) pooled p95, a real one gets < 1 %: not implemented.
- The speckle is in the image, not the estimator (`--ablate 0,2,4,7,9,12`, frame 0 of s/clean,
  s/sunny, s/glare, c/shadow, c/green, s/saturated; median over the 6 frames, plate RMS px raw /
  final): as rendered 0.239 / 0.039 (H), 0.248 / 0.026 (V); without speckle 0.071 / 0.015,
  0.066 / 0.011; without shot and read noise 0.236 / 0.039, 0.246 / 0.029; without texture
  0.238 / 0.037, 0.240 / 0.026; speckle only (no noise, no texture) 0.232 / 0.036, 0.239 /
  0.034, its final error correlated 0.88 / 0.82 with the as-rendered one; another speckle
  and noise draw of the same scene 0.238 / 0.043, 0.250 / 0.024, correlated 0.38 / 0.19.
  So the plates' error is the speckle realisation: the rendered speckle field multiplies the
  laser's irradiance independently of the stripe's position (fully developed, grain 1.2 px,
  `sim.shade.speckle_field`), and each column's intensity-weighted centre is displaced by it
  in the noise-free image itself; no per-column estimator can remove it, and along the stripe
  it averages out only as 1 / √N, which the final smoothing already does over whole plates.

`--set` as in `tail_structure`; `--load` re-analyses a saved `--out`.
"""

from __future__ import annotations

import argparse

import numpy as np

from experiments import common as C
from experiments import tail_structure as T

STAGES = ("raw", "fit", "re6", "final")
MIN_RUN = 100
LAGS = (1, 2, 3, 5, 8, 12, 20, 30, 50, 80, 120)
HALVES = (0, 4, 8, 16, 32, 64, 128, 256)


def stages(image, stripe: str) -> dict[str, np.ndarray]:
    """Centres of every stage (module docstring) of one frame and stripe."""
    import math

    from cslx import segmentation as seg
    from cslx.segmentation import refine
    from cslx.segmentation.profile import fit_centres
    from cslx.segmentation.ridges import noise_std
    from experiments.common import second_pass_inputs

    centres, seen = second_pass_inputs(image, stripe)
    uv = seg.centres_to_pixels(centres, stripe)
    mono, pos, valid, bridged, clipped = (
        seen[k] for k in ("mono", "pos", "valid", "bridged", "clipped")
    )
    sigma, axis = seen["sigma"], seen["axis"]
    use = valid & ~bridged
    out = {}
    for name, sa in (("raw", 0.0), ("re6", refine.SIGMA_REFINE)):
        r, _ = refine.refine_centres(mono, pos, use, sigma=sigma, sigma_along=sa, axis=axis)
        out[name] = np.asarray(r, float)
    half = int(math.ceil(refine.REACH + 4 * sigma))
    fit, found, _, _ = fit_centres(
        mono, pos, use, clipped, noise_std(mono), half=half, axis=axis, reach=refine.REACH
    )
    out["fit"] = np.where(np.asarray(found), np.asarray(fit, float), np.nan)
    out["final"] = uv[:, 1] if stripe == "h" else uv[:, 0]
    out["use"] = np.asarray(use)
    out["uv"] = uv
    return out


def collect(conds, frames, cache):
    rows = []
    for c in conds:
        for i in range(frames):
            image, gt = T.frame(c, i, cache)
            for s in ("h", "v"):
                t = gt["h_v"] if s == "h" else gt["v_u"]
                other = gt["v_u"] if s == "h" else gt["h_v"]
                st = stages(image, s)
                rows.append(
                    dict(
                        c=c, i=i, s=s, t=t, xyz=gt[C.STRIPE_GT[s]], region=T.regions(t, other), **st
                    )  # fmt: skip
                )
        print(f"condition {c} done", flush=True)
    return rows


def mm_errors(row, pos):
    """3-D error (mm) of every centre with position `pos` along the search axis, NaN where
    not matched."""
    from cslx.sensor import default_sensor

    uv = np.array(row["uv"], float)
    k = 1 if row["s"] == "h" else 0
    uv[:, k] = np.where(np.isfinite(uv[:, k]), pos, np.nan)
    err, _, _, _ = C.point_errors(uv, row["xyz"], default_sensor(), C.STRIPE_PLANE[row["s"]])
    m = np.all(np.isfinite(uv), 1) & np.all(np.isfinite(row["xyz"]), 1)
    e = np.full(len(pos), np.nan)
    e[m] = err
    return e


def runs(mask, min_len=MIN_RUN):
    idx = np.flatnonzero(mask)
    if not len(idx):
        return []
    return [r for r in np.split(idx, np.flatnonzero(np.diff(idx) > 1) + 1) if len(r) >= min_len]


def local_line(y, groups, half):
    """Centred least-squares line through ±`half` centres of the same group, value at the
    centre (the window truncated at a group's ends)."""
    out = np.array(y, float)
    if half == 0:
        return out
    for g in groups:
        v = y[g]
        n = len(v)
        j = np.arange(n, dtype=float)
        cs = [np.concatenate([[0], np.cumsum(a)]) for a in (np.ones(n), j, j * j, v, j * v)]
        lo = np.clip(np.arange(n) - half, 0, n)
        hi = np.clip(np.arange(n) + half + 1, 0, n)
        s0, s1, s2, t0, t1 = (c[hi] - c[lo] for c in cs)
        det = s0 * s2 - s1 * s1
        b = np.where(det > 0, (s0 * t1 - s1 * t0) / np.where(det > 0, det, 1), 0.0)
        a = (t0 - b * s1) / s0
        out[g] = a + b * j
    return out


def whole_fit(y, groups, deg: int, min_len: int = MIN_RUN):
    """The least-squares polynomial of degree `deg` through each group of ≥ `min_len`
    centres (one window per straight segment: the longest average the segment allows)."""
    out = np.array(y, float)
    for g in groups:
        if len(g) >= min_len:
            x = np.arange(len(g))
            out[g] = np.polyval(np.polyfit(x, y[g], deg), x)
    return out


def straight(y, ok, threshold: float, reach: int, lag: int = 5):
    """Centres ≥ `reach` from any kink of the estimated path, a kink where the second
    difference at lag `lag`, |y[j+lag] − 2y[j] + y[j−lag]|, exceeds `threshold` px (or is not
    defined): a kink detector that does not see the truth."""
    d2 = np.full(len(y), np.nan)
    yy = np.where(ok, y, np.nan)
    d2[lag:-lag] = yy[2 * lag :] - 2 * yy[lag:-lag] + yy[: -2 * lag]
    bad = ~np.isfinite(d2) | (np.abs(np.nan_to_num(d2)) > threshold)
    bad = np.convolve(bad.astype(float), np.ones(2 * reach + 1), "same") > 0
    return ok & ~bad


def segments(rows):
    """(2b): one polynomial through each straight segment of the final centres, the segments
    from the true regions (oracle) or from the estimated path's kinks (`straight`)."""
    variants = [("as is", None, 0, 0.0, 0)] + [("oracle", None, d, 0.0, 0) for d in (1, 2)]
    variants += [("kinks", None, 2, thr, reach) for thr, reach in
                 ((0.03, 20), (0.05, 20), (0.08, 20), (0.05, 30))]  # fmt: skip
    for s in ("h", "v"):
        rs = [r for r in rows if r["s"] == s]
        print(f"\n{s.upper()}: one polynomial per straight segment of the final centres, p95 mm "
              "(plate / near / toe / cap / all), gross, median")  # fmt: skip
        for mode, _, deg, thr, reach in variants:
            mm, reg = [], []
            for r in rs:
                y = np.asarray(r["final"], float)
                ok = r["use"] & np.isfinite(y)
                if mode != "as is":
                    m = ok & (r["region"] == 0) if mode == "oracle" else straight(y, ok, thr, reach)
                    y = np.where(ok, whole_fit(np.where(ok, y, np.nan), runs(m, 1), deg), y)
                mm.append(mm_errors(r, y))
                reg.append(np.where(ok, r["region"], -1))
            mm, reg = np.concatenate(mm), np.concatenate(reg)
            f = np.isfinite(mm)
            cells = [np.percentile(mm[f & q], 95) for q in (reg == 0, reg == 1, reg == 2,
                                                              reg == 3, reg >= 0)]  # fmt: skip
            print(f"  {mode:6s} deg {deg} kink > {thr:.2f} px ±{reach:2d}: "
                  + " / ".join(f"{c:.4f}" for c in cells)
                  + f"  gross {int((mm[f] > 1).sum())}  median {np.median(mm[f]):.4f}")  # fmt: skip


def structure(rows, names):
    """(1): autocorrelation, correlation length, per-condition amplitude on the plates."""
    for s in ("h", "v"):
        print(f"\n{s.upper()} plates: autocorrelation of the signed px error (median over runs)")
        print("  stage  " + " ".join(f"{lag:>5d}" for lag in LAGS) + "   L(1/e)  offset share")
        for st in STAGES:
            ac = {lag: [] for lag in LAGS}
            offset = []
            for r in rows:
                if r["s"] != s:
                    continue
                e = r[st] - r["t"]
                for run in runs((r["region"] == 0) & r["use"] & np.isfinite(e)):
                    x = e[run]
                    offset.append(np.mean(x) ** 2 / np.mean(x**2))
                    x = x - np.mean(x)
                    v = np.mean(x**2)
                    for lag in LAGS:
                        if lag < len(x) // 2:
                            ac[lag].append(np.mean(x[:-lag] * x[lag:]) / v)
            med = [np.median(ac[lag]) if ac[lag] else np.nan for lag in LAGS]
            length = np.nan
            for k, m in enumerate(med):
                if m < 1 / np.e:
                    lo, mlo = (0, 1.0) if k == 0 else (LAGS[k - 1], med[k - 1])
                    length = lo + (mlo - 1 / np.e) / (mlo - m) * (LAGS[k] - lo)
                    break
            print(f"  {st:6s} " + " ".join(f"{m:5.2f}" for m in med)
                  + f"   {length:6.1f}  {np.median(offset):.2f}")  # fmt: skip
        print(f"{s.upper()} plates per condition: RMS px (raw, fit, re6, final), final p95 mm")
        for c, n in enumerate(names):
            rs = [r for r in rows if r["s"] == s and r["c"] == c]
            if not rs:
                continue
            cells = []
            for st in STAGES:
                e = np.concatenate([(r[st] - r["t"])[(r["region"] == 0) & r["use"]] for r in rs])
                e = e[np.isfinite(e)]
                cells.append(np.sqrt(np.mean(e**2)))
            mm = np.concatenate([r["mm_final"][(r["region"] == 0) & r["use"]] for r in rs])
            mm = mm[np.isfinite(mm)]
            print(f"  {c:2d} {n:16s} " + " ".join(f"{v:.3f}" for v in cells)
                  + f"   p95 {np.percentile(mm, 95):.3f} mm")  # fmt: skip


def windows(rows):
    """(2): p95 (mm) by region against the extra local-line half window."""
    for s in ("h", "v"):
        rs = [r for r in rows if r["s"] == s]
        print(f"\n{s.upper()}: extra centred local line ±L, p95 mm (plate / near / toe / cap / "
              "all) and plate RMS px")  # fmt: skip
        for st in ("raw", "final"):
            for mode in ("blind", "oracle"):
                for half in HALVES:
                    mm, reg, px = [], [], []
                    for r in rs:
                        y = np.asarray(r[st], float)
                        ok = r["use"] & np.isfinite(y)
                        if mode == "blind":
                            groups = runs(ok, 1)
                        else:
                            groups = runs(ok & (r["region"] == 0), 1)
                        y2 = local_line(np.where(ok, y, np.nan), groups, half)
                        y2 = np.where(ok, y2, r["final"])
                        mm.append(mm_errors(r, y2))
                        reg.append(np.where(ok, r["region"], -1))
                        px.append(np.where(ok & (r["region"] == 0), y2 - r["t"], np.nan))
                    mm, reg, px = (np.concatenate(a) for a in (mm, reg, px))
                    cells = []
                    for q in (reg == 0, reg == 1, reg == 2, reg == 3, reg >= 0):
                        e = mm[q & np.isfinite(mm)]
                        cells.append(np.percentile(e, 95) if len(e) else np.nan)
                    px = px[np.isfinite(px)]
                    gross = int(np.sum(mm[np.isfinite(mm)] > 1))
                    print(f"  {st:5s} {mode:6s} ±{half:3d}: " + " / ".join(
                        f"{v:.4f}" for v in cells) + f"   rms {np.sqrt(np.mean(px**2)):.4f}"
                        f"  gross {gross}")  # fmt: skip


ABLATIONS = ("as rendered", "other seed", "no speckle", "no noise", "no texture", "speckle only")


def ablate(conds, cache):
    """(3) Is the plates' error in the rendered image? Each frame of `conds` (frame 0)
    rendered again with the same world, pose and noise key but parts of the image formation
    off (`ABLATIONS`; "other seed": another speckle and noise draw of the same scene,
    "speckle only": no shot / read noise, no texture): plate RMS (px) per stage, and the
    correlation of each variant's final plate error with the as-rendered one."""
    from cslx import sim
    from cslx.sensor import default_sensor
    from experiments.robust_extraction import conditions

    sensor = default_sensor()
    names = conditions()
    acc = {}
    for c in conds:
        kind, nuisance = names[c]
        rng = np.random.default_rng([7100 + c, 0])
        world = sim.random_world(kind, rng)
        pose = sim.random_pose(world, kind, rng, sensor)
        seed = int(rng.integers(2**31))
        nz = {**sim.NUISANCES, **sim.HARD_NUISANCES}[nuisance]
        quiet = dict(read_noise=0.0, electrons_per_dn=1e12)
        variants = {
            "as rendered": (nz, seed, None),
            "other seed": (nz, seed + 1, seed),
            "no speckle": (nz._replace(speckle=0.0), seed, None),
            "no noise": (nz._replace(**quiet), seed, None),
            "no texture": (nz._replace(texture=0.0), seed, None),
            "speckle only": (nz._replace(texture=0.0, **quiet), seed, None),
        }
        base = {}
        for name, (v, sd, scene) in variants.items():
            image, gt = sim.render_frame(sensor, world, pose, v, sd, scene_seed=scene)
            for s in ("h", "v"):
                t = gt["h_v"] if s == "h" else gt["v_u"]
                other = gt["v_u"] if s == "h" else gt["h_v"]
                q0 = T.regions(t, other) == 0
                st = stages(image, s)
                q = q0 & st["use"]
                rms = [np.sqrt(np.nanmean((st[k] - t)[q] ** 2)) for k in STAGES]
                e = np.where(q, st["final"] - t, np.nan)
                if name == "as rendered":
                    base[s] = e
                both = np.isfinite(e) & np.isfinite(base[s])
                rho = np.corrcoef(e[both], base[s][both])[0, 1]
                acc.setdefault((s, name), []).append(rms + [rho])
        print(f"condition {c} {kind}/{nuisance} done", flush=True)
    for s in ("h", "v"):
        print(f"{s.upper()}: median over {len(conds)} frames: raw / fit / re6 / final px, corr")
        for name in ABLATIONS:
            m = np.nanmedian(np.array(acc[(s, name)]), 0)
            print(f"  {name:12s} " + " ".join(f"{x:.4f}" for x in m))


def main():
    a = argparse.ArgumentParser(description=__doc__)
    a.add_argument("--frames", type=int, default=3)
    a.add_argument("--cache", default="/tmp/ext11g/frames")
    a.add_argument("--set", action="append", default=[])
    a.add_argument("--out", default="")
    a.add_argument("--load", default="")
    a.add_argument("--no-windows", action="store_true")
    a.add_argument("--ablate", default="", help="comma-separated conditions: (3) only")
    args = a.parse_args()
    from experiments.robust_extraction import conditions

    names = [f"{k[0]}/{n}" for k, n in conditions()]
    if args.ablate:
        ablate([int(c) for c in args.ablate.split(",")], args.cache)
        return
    if args.load:
        rows = list(np.load(args.load, allow_pickle=True))
    else:
        T.apply_sets(args.set)
        rows = collect(range(18), args.frames, args.cache)
        for r in rows:
            r["mm_final"] = mm_errors(r, r["final"])
        if args.out:
            np.save(args.out, np.array(rows, dtype=object), allow_pickle=True)
    structure(rows, names)
    if not args.no_windows:
        windows(rows)
        segments(rows)


if __name__ == "__main__":
    main()
