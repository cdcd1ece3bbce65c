"""Figure 7 of the paper: one frame as captured, in R, in gray and in R−G.

A rendered T-intersection in sunshine (sunlight is near-grey, the laser red with a little
green leakage). Below each monochrome image, one column's profile shows how much of the
background each space keeps; the title gives the space's kurtosis score (normalized form of
eqs. (9)–(12), columns). Also shows the space the 74-candidate search picks.

Writes `results/fig07_colour_spaces.png`.
"""

from __future__ import annotations

import numpy as np

from experiments import common as C  # noqa: E402

SPACES = {"R": (1.0, 0.0, 0.0), "gray": (0.299, 0.587, 0.114), "R−G": (1.0, -1.0, 0.0)}


def main(seed: int = 7, nuisance: str = "sunny", kind: str = "cross", out: str = str(C.RESULTS)):
    """Draw Figure 7; return one row per space (weights, kurtosis score, stripe contrast)."""
    import matplotlib.pyplot as plt

    from cslx.segmentation.colour import kurtosis_objective, monochrome, search_space

    image, gt = C.frame_at(kind, nuisance, seed, 0)
    best, _ = search_space(image)
    spaces = dict(SPACES)
    spaces[f"kurtosis pick ({', '.join(f'{x:g}' for x in np.asarray(best))})"] = tuple(
        float(x) for x in np.asarray(best)
    )
    col = 320
    v_true = gt["h_v"][col]
    fig, axes = plt.subplots(
        2,
        1 + len(spaces),
        figsize=(4.0 * (1 + len(spaces)), 4.6),
        gridspec_kw=dict(height_ratios=[3, 1.3]),
    )
    C.image_axis(axes[0, 0], image, f"captured ({kind}, {nuisance}, seed {seed})")
    axes[0, 0].axvline(col, color="w", lw=0.6, ls=":")
    for c in range(3):
        axes[1, 0].plot(image[:, col, c], color="rgb"[c], lw=0.8)
    axes[1, 0].set_title(f"column {col}: R, G, B", fontsize=8)
    rows = []
    for k, (name, w) in enumerate(spaces.items(), start=1):
        I = np.asarray(monochrome(image, w))
        score = float(kurtosis_objective(w, image))
        C.image_axis(axes[0, k], I, f"{name}: kurtosis {score:.1f}", cmap="gray")
        prof = I[:, col]
        axes[1, k].plot(prof, color="k", lw=0.8)
        axes[1, k].axvline(v_true, color="tab:red", lw=0.6, ls="--")
        axes[1, k].set_title(f"column {col} (red: true stripe row)", fontsize=8)
        near = np.abs(np.arange(len(prof)) - v_true) <= 4
        peak = float(prof[near].max())
        bg = float(np.median(prof[~near]))
        spread = float(prof[~near].std())
        rows.append(
            dict(
                space=name,
                w_r=w[0],
                w_g=w[1],
                w_b=w[2],
                kurtosis=score,
                stripe_minus_background=peak - bg,
                background_std=spread,
                contrast_to_noise=(peak - bg) / max(spread, 1e-9),
            )
        )
    for a in axes[1]:
        a.tick_params(labelsize=7)
        a.set_xlabel("row v (px)", fontsize=7)
    fig.tight_layout()
    fig.suptitle(
        "Figure 7: one frame in three colour spaces (+ the kurtosis search's pick)",
        fontsize=10,
        y=1.04,
    )
    path = C.save_figure(fig, out, "fig07_colour_spaces.png")
    print(f"wrote {path}")
    for r in rows:
        print(f"  {r['space']:<28} kurtosis {r['kurtosis']:8.2f}  CNR {r['contrast_to_noise']:.1f}")
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 1, 7)
    args = a.parse_args()
    main(seed=args.seed, out=args.out)
