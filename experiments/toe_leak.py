"""Where the bead toes' error comes from (issue 11, the p95): each stage of the linked detector
at the bends of the true path, the error signed by the bend's curvature.

For the development frames of `experiments.tail_structure` (seeds 7100 + condition, frames
0 … `--frames` − 1, cached), both stripes, the default `linked` detector runs once; its second
pass (`cslx.segmentation.refine.second_pass`) is intercepted to keep its inputs (the
monochrome image, the first pass's smoothed path p, its masks and σ), and the same
re-measurement is repeated with other references and along-path averages:

- ``first``: the first pass's path p (its 6 px smoothing along the image axis rounds a kink);
- ``re_p_0`` / ``re_t_0``: each column's own centre (`refine.refine_centres`, no along-path
  average) around p / around the ground truth t: what the image says per column (a bias
  here would be the ground truth's definition, Steger's σ across the kink or the wrong ridge);
- ``re_p_6`` / ``re_t_6``: the same averaged along the path (σ `refine.SIGMA_REFINE`), which
  returns ref + G∗(c − ref): a reference error narrower than G passes;
- ``final_p`` (the detector's output) / ``final_t``: the whole second pass (profile fit, final
  smoothing) around p / around t.

Prints, per stripe, the curvature-signed mean (RMS) pixel error by distance to the nearest
bend of t (|t[j+5] − 2t[j] + t[j−5]| > 0.1 px, `tail_structure.regions`), the toe pool
(within ±10 centres) and its 90th percentile of |error|. `--set` as in `tail_structure`.
"""

from __future__ import annotations

import argparse

import numpy as np

from experiments import tail_structure as T

STAGES = ("first", "re_p_0", "re_p_6", "final_p", "re_t_0", "re_t_6", "final_t")


def stages(image, stripe: str, t: np.ndarray) -> dict[str, np.ndarray]:
    """Centres of every stage (module docstring) of one frame and stripe."""
    import jax.numpy as jnp

    from cslx.segmentation import refine, robust
    from experiments.common import second_pass_inputs

    _, seen = second_pass_inputs(image, stripe)
    mono, pos, valid, bridged, clipped = (
        seen[k] for k in ("mono", "pos", "valid", "bridged", "clipped")
    )
    sigma, axis = seen["sigma"], seen["axis"]
    use = valid & ~bridged
    truth = jnp.asarray(np.where(np.isfinite(t), t, np.nan_to_num(np.asarray(pos))), pos.dtype)
    out = {"first": np.asarray(pos)}
    for name, ref in (("p", pos), ("t", truth)):
        for sa in (0.0, refine.SIGMA_REFINE):
            r, _ = refine.refine_centres(mono, ref, use, sigma=sigma, sigma_along=sa, axis=axis)
            out[f"re_{name}_{0 if sa == 0 else 6}"] = np.asarray(r)
        final = robust.second_pass(mono, ref, valid, bridged, clipped, sigma=sigma, axis=axis)
        out[f"final_{name}"] = np.asarray(final)
    out["valid"] = np.asarray(use)
    return out


def by_distance(rows, stripe: str):
    """{stage: {d: signed errors}} at distance d (−12 … 12) from the nearest bend of t."""
    acc = {k: {} for k in STAGES}
    for r in rows:
        if r["s"] != stripe:
            continue
        t = r["t"]
        n = len(t)
        d2 = np.full(n, np.nan)
        d2[5:-5] = t[10:] - 2 * t[5:-5] + t[:-10]
        bend = np.abs(np.nan_to_num(d2)) > 0.1
        if not bend.any():
            continue
        j = np.arange(n)
        b = j[bend]
        k = np.argmin(np.abs(j[:, None] - b[None, :]), 1)
        dist, sign = j - b[k], np.sign(d2[b[k]])
        ok = r["valid"] & np.isfinite(t) & (r["region"] != 4) & (r["region"] != 5)
        for name in STAGES:
            e = r[name] - t
            for d in range(-12, 13):
                q = (dist == d) & ok & np.isfinite(e)
                acc[name].setdefault(d, []).append(sign[q] * e[q])
    return {k: {d: np.concatenate(v) for d, v in a.items()} for k, a in acc.items()}


def main():
    a = argparse.ArgumentParser(description=__doc__)
    a.add_argument("--frames", type=int, default=3)
    a.add_argument("--cache", default="/tmp/ext11g/frames")
    a.add_argument("--set", action="append", default=[])
    args = a.parse_args()
    T.apply_sets(args.set)
    rows = []
    for c in range(18):
        for i in range(args.frames):
            image, gt = T.frame(c, i, args.cache)
            for s in ("h", "v"):
                t = gt["h_v"] if s == "h" else gt["v_u"]
                other = gt["v_u"] if s == "h" else gt["h_v"]
                rows.append(
                    dict(c=c, i=i, s=s, t=t, region=T.regions(t, other), **stages(image, s, t))
                )
    for s in ("h", "v"):
        acc = by_distance(rows, s)
        print(f"{s.upper()}: curvature-signed mean (RMS) px by distance to the nearest bend of t")
        print("  d " + "".join(f"{k:>16s}" for k in STAGES))
        for d in range(-12, 13):
            x = [acc[k][d] for k in STAGES]
            cells = "".join(f"  {np.mean(v):+.3f} ({np.sqrt(np.mean(v**2)):.3f})" for v in x)
            print(f"{d:+3d}{cells}  n {len(x[0])}")
        pool = [np.concatenate([acc[k][d] for d in range(-10, 11)]) for k in STAGES]
        print("toe" + "".join(f"  {np.mean(v):+.3f} ({np.sqrt(np.mean(v**2)):.3f})" for v in pool))
        print("p90" + "".join(f"  {np.percentile(np.abs(v), 90):15.3f}" for v in pool))


if __name__ == "__main__":
    main()
