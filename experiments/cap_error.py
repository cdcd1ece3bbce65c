"""The vertical stripe's bead caps and near-bend plates (issue 11, the p95): by frame, by cause.

Input: the per-centre rows of `experiments.plate_speckle --out` (development seeds 7100 +
condition, frames 0 … 2; stages ``raw`` / ``re6`` / ``fit`` / ``final`` and the regions of
`experiments.tail_structure.regions`). Frames from its cache (`--cache`).

(1) `--rows`: the V caps (code 3) and near-bend plates (code 1) per frame and condition:
p95 (mm), signed px error per stage, and features of each centre's image row: the core
clipped (an R = 255 within ±3 px of the truth), the background's green level and its
slope across the stripe (G averaged over the profile's 3 outer pixels on each side: the sun's
sheen under the stripe), the true path's second difference (curvature).

(2) `--ablate c:i,…`: the listed frames rendered again (same world, pose, noise key, scene
conditions) with parts of the image formation off: no sheen and glints; no sun at all; no
speckle; a laser-only image (no background, speckle or noise, power 150 so the core does not
clip) measured by the detector and by an oracle (each row's intensity centroid of R over
±4 px around the truth: where the rendered laser's light is, against the ground truth's
plane-surface intersection). V p95 (mm) of caps / near / plates.

(3) `--rows`: clipped cores' flank levels (`flank_ratio`); (4) one polynomial per true
segment (`oracle_fits`).

Findings (development seeds 7100–7117, frames 0–2, 54 frames; the default linked detector at
2371738; `plate_speckle --frames 3 --out` then `--rows`; `--ablate` on the 20 frames with V
caps):

- Where: the V caps (1076 centres, p95 0.317 mm) are a quarter one frame: 2_1 (straight
  scene, sunny) holds 266 of them (the V stripe climbs onto the bead at a grazing angle and
  runs on it for ≈ 270 rows), p95 0.604 mm; without it the caps' p95 is 0.228 mm and the V
  pooled p95 0.1342 → 0.1310 mm (near-bend V plates 0.1465 → 0.1407). Caps' p95 per
  condition: c/printed 0.371, c/blue 0.250, c/clean 0.218, c/sunny 0.191, c/saturated 0.147,
  c/saturated_sunny 0.131, c/glare 0.104, c/shadow 0.099, c/green 0.099 (s/sunny 0.604).
- By cause (`--ablate`, the 20 frames pooled, V p95 mm caps / near-bend / plates): as
  rendered 0.317 / 0.142 / 0.108; no glints 0.207 / 0.138 / 0.110; no sheen or glints 0.183 /
  0.134 / 0.104; no sun 0.180 / 0.137 / 0.105; no speckle 0.290 / 0.083 / 0.075; neither sun
  nor speckle 0.117 / 0.079 / 0.068. So the caps' tail is the bead's glints (2_1: 0.604 →
  0.128 without glints alone) and the laser speckle (c/clean 1_1 / 1_2: 0.172 / 0.288 →
  0.045 / 0.054 without speckle; c/blue 11_1 0.260 → 0.068; c/saturated 13_1 / 13_2 0.157 /
  0.134 → 0.080 / 0.057), plus the printed target (17_0: 0.426, unchanged by either: a thin
  stripe over black and white squares). The near-bend V plates are speckle (0.142 → 0.083);
  the sun moves them < 0.01 mm.
- The glints' pixels (2_1, rows 150–216): white glint spots (G, B = 255) beside the
  stripe's R-clipped core join its clipped run, so the run reaches 7–9 px and the
  clipped-core fill (`robust.fill_clipped`: the run's middle) moves with it: per-row
  (``raw``) errors −1.59 px at row 208, +0.80 at row 168, a ±1 px wave over 70 rows that the
  final smoothing keeps (−1.10 / +0.43 px). The fill's assumption (white glints have grey
  flanks and stay dark) fails where a glint touches the core. Across the V caps the
  background green slope across the stripe flags them: |G slope| > 30 DN (21 % of the caps)
  p95 0.696 mm, the rest 0.218.
- Not the cause: the ground truth on a curved cap (the laser-only image's per-row centroid
  about the truth: mean −0.008 px, RMS 0.104 px on the caps, 0.109 on the plates: the same;
  that RMS is the laser's texture and pixel sampling, not the cap); the cap's curvature (the
  signed error against the true path's second difference at lag 5: slope 1.0 / 0.8 px/px
  raw / final, correlation 0.07 / 0.19, the caps' d2 RMS 0.05 px: < 0.05 px); the crossing
  (4 % of the V caps within 40 rows of it, p95 0.105 mm; near-bend 4 %, 0.32 mm); clipping
  as such (70 % of the V caps clipped, p95 0.328 against 0.312 unclipped).
- What an estimator could still take (offline bounds, no change made): (4) one quadratic
  through each whole true cap of the final centres: V caps 0.317 → 0.268 mm (without 2_1
  0.228 → 0.229; cubic 0.200); through the true near-bend + plate segments: near 0.147 →
  0.122 — the speckle's √N floor over a cap of ≈ 45 rows stays above 0.1 mm, and a real kink
  detector gets less than these oracles (`plate_speckle`: < 1 % pooled). (3) A clipped core
  whose two unclipped neighbours differ (a Gaussian crossing two clip levels: centre
  (u_L + u_R)/2 + s² x, x = −ln(m_L / m_R) / (u_R − u_L)) explains part of the per-row error
  (correlation −0.37 V / −0.33 H, −0.55 on 2_1): raw RMS 0.249 → 0.231 px (V) with k fitted
  in-sample; added to the final centres (k x smoothed along the path, σ 3–12 px, ½ or all of
  it) it moved V pooled p95 0.1342 → 0.1333–0.1396 and H 0.1285 → 0.1269–0.1313, the V caps
  0.317 → 0.279–0.291: in-sample and ≤ 1 % pooled, not implemented.
- Aside: the detector on the laser-only image (no background, speckle or noise) does worse
  than on the rendered frames (p95 0.301 / 0.202 / 0.169 mm): a noise-free frame is no
  real input (its noise scale is 0); the cause was not examined.

Run: `python -m experiments.cap_error --rows ROWS.npy` and
`python -m experiments.cap_error --ablate 2:1,1:1,3:0,11:1,17:0`.
"""

from __future__ import annotations

import argparse

import numpy as np

from experiments import common as C
from experiments import tail_structure as T

STAGES = ("raw", "re6", "fit", "final")


def features(row, cache: str):
    """Per-centre image features of one row of `plate_speckle` (module doc (1))."""
    image, _ = T.frame(row["c"], row["i"], cache)
    im = image.astype(int)
    t = row["t"]
    n = len(t)
    clip = np.zeros(n, bool)
    g_bg = np.full(n, np.nan)
    g_slope = np.full(n, np.nan)
    for j in np.flatnonzero(np.isfinite(t)):
        u0 = int(round(t[j]))
        lo = u0 - 6
        prof = im[j, lo : u0 + 7] if row["s"] == "v" else im[lo : u0 + 7, j]
        if lo < 0 or len(prof) < 13:
            continue
        clip[j] = bool((prof[3:10, 0] == 255).any())
        g = prof[:, 1]
        g_bg[j] = 0.5 * (g[:3].mean() + g[-3:].mean())
        g_slope[j] = g[-3:].mean() - g[:3].mean()
    d2 = np.full(n, np.nan)
    d2[5:-5] = t[10:] - 2 * t[5:-5] + t[:-10]
    cross = np.flatnonzero(row["region"] == 4)
    j = np.arange(n)
    dist = np.min(np.abs(j[:, None] - cross[None, :]), 1) if len(cross) else np.full(n, 999)
    return clip, g_bg, g_slope, d2, dist


def by_frame(rows, names, cache: str, stripe: str = "v"):
    """(1): the caps and near-bend plates per frame, per condition, per feature."""
    for reg, label in ((3, "caps"), (1, "near-bend plates")):
        acc = {k: [] for k in ("mm", "clip", "g", "gs", "d2", "dx", "fr", *STAGES)}
        print(f"\n{stripe.upper()} {label}: frame, n, p95 mm, signed px mean (raw re6 fit final),"
              " clipped share, background G, |G slope| median")  # fmt: skip
        for r in rows:
            if r["s"] != stripe:
                continue
            q = (r["region"] == reg) & np.isfinite(r["mm_final"])
            if not q.any():
                continue
            clip, g, gs, d2, dx = features(r, cache)
            acc["mm"].append(r["mm_final"][q])
            for k, v in (("clip", clip), ("g", g), ("gs", gs), ("d2", d2), ("dx", dx)):
                acc[k].append(v[q])
            acc["fr"].append(np.full(q.sum(), 10 * r["c"] + r["i"]))
            for st in STAGES:
                acc[st].append((r[st] - r["t"])[q])
            print(f"  {r['c']:2d}_{r['i']} {names[r['c']]:18s} {q.sum():4d} "
                  f"{np.percentile(r['mm_final'][q], 95):.3f}  "
                  + " ".join(f"{np.nanmean((r[st] - r['t'])[q]):+.3f}" for st in STAGES)
                  + f"  {clip[q].mean():.2f} {np.nanmedian(g[q]):5.0f}"
                  f" {np.nanmedian(np.abs(gs[q])):5.1f}")  # fmt: skip
        a = {k: np.concatenate(v) for k, v in acc.items()}
        mm = a["mm"]
        print(f"  pooled n {len(mm)} p95 {np.percentile(mm, 95):.4f} mm")
        big = [f for f in set(a["fr"]) if (a["fr"] == f).sum() >= 20]
        worst = max(big, key=lambda f: np.percentile(mm[a["fr"] == f], 95))
        tests = (
            ("clipped core", a["clip"]),
            ("unclipped", ~a["clip"]),
            ("|G slope| > 30 DN", np.abs(a["gs"]) > 30),
            ("|G slope| <= 30 DN", np.abs(a["gs"]) <= 30),
            ("<= 40 from the crossing", a["dx"] <= 40),
            ("> 40 from the crossing", a["dx"] > 40),
            (f"without frame {worst // 10}_{worst % 10}", a["fr"] != worst),
        )
        for lab, q in tests:
            if q.sum() >= 5:
                ef, er = np.nanmean(a["final"][q]), np.nanmean(a["raw"][q])
                print(f"  {lab:24s} n {q.sum():5d} ({100 * q.mean():4.1f} %) p95 "
                      f"{np.percentile(mm[q], 95):.4f} signed px final {ef:+.3f} "
                      f"raw {er:+.3f}")  # fmt: skip
        q = np.isfinite(a["d2"]) & (a["fr"] != worst)
        for st in ("raw", "final"):
            m = q & np.isfinite(a[st])
            b = np.polyfit(a["d2"][m], a[st][m], 1)[0]
            rho = np.corrcoef(a["d2"][m], a[st][m])[0, 1]
            print(f"  {st}: signed error vs the true d2 (lag 5): slope {b:+.3f} px/px, corr "
                  f"{rho:+.2f}, d2 RMS {np.sqrt(np.mean(a['d2'][m] ** 2)):.3f} px")  # fmt: skip
        q = np.isfinite(a["gs"]) & np.isfinite(a["raw"])
        for lab, m in (("clipped", q & a["clip"]), ("unclipped", q & ~a["clip"])):
            if m.sum() > 10:
                rho = np.corrcoef(a["gs"][m], a["raw"][m])[0, 1]
                print(f"  raw signed error vs G slope ({lab}): corr {rho:+.2f}")
        for c in sorted(set(a["fr"] // 10)):
            q = a["fr"] // 10 == c
            print(f"   {names[c]:18s} n {q.sum():4d} p95 {np.percentile(mm[q], 95):.3f}")


def flank_ratio(rows, cache: str):
    """(3): a clipped core's two flank levels. Where the unclipped neighbours m_L, m_R
    (monochrome R − G) of the clipped run [u_L + 1, u_R − 1] around the truth differ, a
    Gaussian core of std s crossing two different clip levels has its centre at
    (u_L + u_R) / 2 − s² ln(m_L / m_R) / (u_R − u_L), not at the run's middle; x =
    −ln(m_L / m_R) / (u_R − u_L) is the regressor. Per-row (``raw``) error against x, the
    least-squares k of raw + k x, and the RMS before / after, per condition."""
    from experiments.robust_extraction import conditions

    names = [f"{k[0]}/{n}" for k, n in conditions()]
    out = {}
    for r in rows:
        image, _ = T.frame(r["c"], r["i"], cache)
        img = image.astype(float) if r["s"] == "v" else image.astype(float).transpose(1, 0, 2)
        red, mono = img[..., 0], img[..., 0] - img[..., 1]
        t = r["t"]
        for j in np.flatnonzero(np.isfinite(t) & np.isfinite(r["raw"]) & r["use"]):
            u0 = int(round(t[j]))
            cl = red[j] == 255
            if u0 < 14 or u0 > red.shape[1] - 15 or not cl[u0 - 1 : u0 + 2].any():
                continue
            a = b = int(np.flatnonzero(cl[u0 - 1 : u0 + 2])[0]) + u0 - 1
            while cl[a - 1] and a > u0 - 12:
                a -= 1
            while cl[b + 1] and b < u0 + 12:
                b += 1
            m_l, m_r = mono[j, a - 1], mono[j, b + 1]
            if cl[a - 1] or cl[b + 1] or min(m_l, m_r) <= 2:
                continue
            x = -np.log(m_l / m_r) / (b - a + 2)
            key = (r["s"], r["c"])
            out.setdefault(key, []).append((r["raw"][j] - t[j], x, 10 * r["c"] + r["i"]))
    for s in ("h", "v"):
        a = np.concatenate([np.array(v) for k, v in out.items() if k[0] == s])
        k = -np.sum(a[:, 0] * a[:, 1]) / np.sum(a[:, 1] ** 2)

        def rms(b, k=k):
            return np.sqrt(np.mean(b[:, 0] ** 2)), np.sqrt(np.mean((b[:, 0] + k * b[:, 1]) ** 2))

        print(f"\n{s.upper()} clipped cores (n {len(a)}): raw error vs x corr "
              f"{np.corrcoef(a[:, 0], a[:, 1])[0, 1]:+.2f}, k {k:.2f} px², raw RMS "
              "%.3f -> %.3f px" % rms(a))  # fmt: skip
        for c in sorted({c for (ss, c) in out if ss == s}):
            b = np.array(out[(s, c)])
            if len(b) >= 50:
                print(f"   {names[c]:18s} n {len(b):5d} raw RMS %.3f -> %.3f" % rms(b))
        b = a[a[:, 2] == 21]
        if s == "v" and len(b):
            print(f"   frame 2_1 n {len(b)} corr {np.corrcoef(b[:, 0], b[:, 1])[0, 1]:+.2f} "
                  "raw RMS %.3f -> %.3f" % rms(b))  # fmt: skip


def oracle_fits(rows):
    """(4): one polynomial (degree 2 / 3) through each true segment of the ``final`` (and
    ``raw``) centres: the caps (code 3 runs), the near-bend plates with their plates (codes
    0 and 1): the longest average a perfect segmentation would allow there."""
    from experiments import plate_speckle as P

    for s in ("v", "h"):
        rs = [r for r in rows if r["s"] == s]
        for name, codes, reg in (("caps", (3,), 3), ("near", (0, 1), 1)):
            for src, deg in (("as is", 0), ("final", 2), ("final", 3), ("raw", 2)):
                mm = []
                for r in rs:
                    y = np.asarray(r["final"], float)
                    ok = r["use"] & np.isfinite(y)
                    if src != "as is":
                        yy = np.asarray(r[src], float)
                        ok2 = ok & np.isfinite(yy)
                        g = P.runs(ok2 & np.isin(r["region"], codes), 1)
                        yy = P.whole_fit(np.where(ok2, yy, np.nan), g, deg, min_len=deg + 3)
                        y = np.where(ok2, yy, y)
                    e = P.mm_errors(r, y)
                    mm.append(e[ok & (r["region"] == reg) & np.isfinite(e)])
                mm = np.concatenate(mm)
                print(f"  {s.upper()} {name:5s} {src:5s} deg {deg}: p95 "
                      f"{np.percentile(mm, 95):.4f} mm")  # fmt: skip


VARIANTS = (
    "as rendered",
    "no glint",
    "no sheen/glint",
    "no sun",
    "no speckle",
    "no sun/speckle",
    "laser only",
)


def stripe_mm(image, gt, stripe: str):
    """The default detector's 3-D errors (mm, NaN where unmatched) and pixel positions."""
    from cslx import segmentation as seg
    from cslx.sensor import default_sensor

    uv = seg.centres_to_pixels(seg.extract(image, "linked", stripe=stripe), stripe)
    xyz = gt[C.STRIPE_GT[stripe]]
    err, _, _, _ = C.point_errors(uv, xyz, default_sensor(), C.STRIPE_PLANE[stripe])
    m = np.all(np.isfinite(uv), 1) & np.all(np.isfinite(xyz), 1)
    e = np.full(len(uv), np.nan)
    e[m] = err
    return e, uv[:, 0] if stripe == "v" else uv[:, 1]


def oracle(image, t, stripe: str, half: int = 4):
    """Each row's (column's) centroid of R within ±`half` px of the truth: where the
    rendered light is (a background-free image)."""
    r = image[..., 0].astype(float)
    if stripe == "h":
        r = r.T
    out = np.full(len(t), np.nan)
    for j in np.flatnonzero(np.isfinite(t)):
        u0 = int(round(t[j]))
        if u0 - half < 0 or u0 + half >= r.shape[1]:
            continue
        u = np.arange(u0 - half, u0 + half + 1)
        w = r[j, u]
        if w.sum() > 0:
            out[j] = np.sum(w * u) / w.sum()
    return out


def ablate(frames, stripe: str = "v"):
    """(2): the frames rendered with parts of the image formation off (module doc)."""
    from cslx import sim
    from cslx.sensor import default_sensor
    from experiments.robust_extraction import conditions

    sensor = default_sensor()
    conds = conditions()
    acc = {}
    for c, i in frames:
        kind, nuisance = conds[c]
        rng = np.random.default_rng([7100 + c, i])
        world = sim.random_world(kind, rng)
        pose = sim.random_pose(world, kind, rng, sensor)
        seed = int(rng.integers(2**31))
        nz = {**sim.NUISANCES, **sim.HARD_NUISANCES}[nuisance]
        quiet = dict(read_noise=0.0, electrons_per_dn=1e12, speckle=0.0)
        variants = {
            "as rendered": nz,
            "no glint": nz._replace(glint=0.0),
            "no sheen/glint": nz._replace(sheen=0.0, glint=0.0),
            "no sun": nz._replace(sun=0.0, sheen=0.0, glint=0.0),
            "no speckle": nz._replace(speckle=0.0),
            "no sun/speckle": nz._replace(sun=0.0, sheen=0.0, glint=0.0, speckle=0.0),
            "laser only": nz._replace(
                ambient=0.0, sun=0.0, sheen=0.0, glint=0.0, laser_power=150.0, **quiet
            ),
        }
        line = f"  {c:2d}_{i} {kind[0]}/{nuisance:16s}"
        for name, v in variants.items():
            image, gt = sim.render_frame(sensor, world, pose, v, seed)
            if name == "as rendered":
                cached, _ = T.frame(c, i, "/tmp/ext11g/frames")
                assert np.array_equal(cached, image), "re-render differs from the cache"
            t = gt["h_v"] if stripe == "h" else gt["v_u"]
            other = gt["v_u"] if stripe == "h" else gt["h_v"]
            reg = T.regions(t, other)
            mm, _ = stripe_mm(image, gt, stripe)
            acc.setdefault(name, []).append((mm, reg))
            if name == "laser only":
                o = oracle(image, t, stripe) - t
                acc.setdefault("oracle px", []).append((o, reg))
            q = (reg == 3) & np.isfinite(mm)
            line += f" {np.percentile(mm[q], 95) if q.any() else np.nan:.3f}"
        print(line + "   (cap p95 mm per variant)", flush=True)
    print(f"\n{stripe.upper()} pooled over {len(frames)} frames: p95 mm caps / near / plates")
    for name in VARIANTS:
        mm = np.concatenate([m for m, _ in acc[name]])
        reg = np.concatenate([g for _, g in acc[name]])
        cells = []
        for k in (3, 1, 0):
            e = mm[(reg == k) & np.isfinite(mm)]
            cells.append(np.percentile(e, 95) if len(e) else np.nan)
        print(f"  {name:15s} " + " / ".join(f"{x:.4f}" for x in cells))
    o = np.concatenate([m for m, _ in acc["oracle px"]])
    reg = np.concatenate([g for _, g in acc["oracle px"]])
    for k, lab in ((3, "caps"), (1, "near"), (0, "plates")):
        e = o[(reg == k) & np.isfinite(o)]
        p95 = np.percentile(np.abs(e), 95)
        print(f"  oracle centroid − truth on {lab}: mean {np.mean(e):+.3f} px, RMS "
              f"{np.sqrt(np.mean(e**2)):.3f}, p95 |·| {p95:.3f} px")  # fmt: skip


def main():
    a = argparse.ArgumentParser(description=__doc__)
    a.add_argument("--rows", default="", help="plate_speckle --out file")
    a.add_argument("--cache", default="/tmp/ext11g/frames")
    a.add_argument("--stripe", default="v", choices=("h", "v"))
    a.add_argument("--ablate", default="", help="frames c:i,c:i,…")
    args = a.parse_args()
    from experiments.robust_extraction import conditions

    names = [f"{k[0]}/{n}" for k, n in conditions()]
    if args.rows:
        rows = list(np.load(args.rows, allow_pickle=True))
        by_frame(rows, names, args.cache, args.stripe)
        flank_ratio(rows, args.cache)
        print("\n(4) one polynomial per true segment (oracle)")
        oracle_fits(rows)
    if args.ablate:
        frames = [tuple(int(x) for x in f.split(":")) for f in args.ablate.split(",")]
        ablate(frames, args.stripe)


if __name__ == "__main__":
    main()
