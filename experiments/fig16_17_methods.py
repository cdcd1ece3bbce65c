"""Figures 16 and 17 of the paper: segmentation results and error curves of the five methods.

One rendered frame (a straight weld in sunshine with glints) is segmented by CM, LA, QA, AA
and MED in R and in R−G (horizontal stripe). Figure 16: the centres of each method drawn on
a crop of the frame around the bead. Figure 17: the 3-D error (mm) of every column along the
stripe, per method, in R and in R−G (a missing column shows as a gap; the fraction detected
is in the legend).

Writes `results/fig16_17_methods.png`.
"""

from __future__ import annotations

import numpy as np

from experiments import common as C  # noqa: E402


def main(seed: int = 5, nuisance: str = "sunny", kind: str = "straight", out: str = str(C.RESULTS)):
    """Draw Figures 16–17; return per (space, method) the error summary on this frame."""
    import matplotlib.pyplot as plt

    from cslx.sensor import default_sensor, triangulate

    sensor = default_sensor()
    image, gt = C.frame_at(kind, nuisance, seed, 0, sensor)
    methods = C.PAPER_METHODS
    hv = gt["h_v"]
    v_mid = float(np.nanmedian(hv))
    top, bottom = int(max(v_mid - 70, 0)), int(min(v_mid + 70, image.shape[0]))
    fig = plt.figure(figsize=(20, 7.2))
    gs = fig.add_gridspec(3, len(methods), height_ratios=[1, 1, 2.2], hspace=0.3, wspace=0.05)
    rows = []
    for r, space in enumerate(("r", "r-g")):
        mono = C.mono(image, space)
        ax_err = fig.add_subplot(gs[2, :2] if r == 0 else gs[2, 2:4])
        for c, m in enumerate(methods):
            uv = C.centres_for(image, m, C.SPACES[space], "h")
            err, px, n_gt, _ = C.point_errors(uv, gt["h_xyz"], sensor, 0)
            ax = fig.add_subplot(gs[r, c])
            C.image_axis(ax, mono[top:bottom], None, cmap="gray")
            ok = np.isfinite(uv[:, 1])
            ax.plot(uv[ok, 0], uv[ok, 1] - top, ".", ms=1.2, color="red")
            ax.set_xlim(-0.5, image.shape[1] - 0.5)
            ax.set_ylim(bottom - top - 0.5, -0.5)  # centres off the crop are off the figure
            det = len(err) / max(n_gt, 1)
            ax.set_title(
                f"{C.METHOD_LABEL[m]} in {C.SPACE_LABEL[space]}: median "
                f"{np.median(err) if len(err) else np.nan:.3f} mm, det. {det:.2f}",
                fontsize=8,
            )
            # Error per column (NaN where no estimate).
            xyz = np.asarray(triangulate(sensor, np.where(ok[:, None], uv, 320.0), 0))
            e_col = np.where(ok, np.linalg.norm(xyz - gt["h_xyz"], axis=1), np.nan)
            ax_err.plot(
                np.arange(len(e_col)),
                e_col,
                lw=0.8,
                color=C.METHOD_COLOUR[m],
                label=f"{C.METHOD_LABEL[m]} (det. {det:.2f})",
            )
            rows.append(
                dict(
                    space=space,
                    method=m,
                    mean_mm=float(np.mean(err)) if len(err) else np.nan,
                    median_mm=float(np.median(err)) if len(err) else np.nan,
                    p95_mm=float(np.percentile(err, 95)) if len(err) else np.nan,
                    detection_rate=det,
                )
            )
        ax_err.set_yscale("log")
        ax_err.set_ylim(1e-3, 300)
        ax_err.axhline(1.0, color="k", lw=0.5, ls=":")
        ax_err.set_xlim(0, len(hv) - 1)
        ax_err.set_xlabel("image column u (px)", fontsize=8)
        if r == 0:
            ax_err.set_ylabel("3-D error (mm)", fontsize=8)
        ax_err.set_title(f"Figure 17: error along the stripe, {C.SPACE_LABEL[space]}", fontsize=9)
        ax_err.legend(fontsize=7, ncol=2, loc="upper right")
        ax_err.tick_params(labelsize=7)
    ax_img = fig.add_subplot(gs[2, 4])
    C.image_axis(ax_img, image, f"captured ({kind}, {nuisance}, seed {seed})")
    ax_img.axhspan(top, bottom, color="y", alpha=0.15)
    fig.suptitle(
        f"Figure 16: centres (red) of the five methods on rows {top}–{bottom} of the "
        "frame, in R (top) and R−G (middle)",
        fontsize=10,
    )
    path = C.save_figure(fig, out, "fig16_17_methods.png")
    print(f"wrote {path}")
    for r in rows:
        print(
            f"  {r['space']:<4} {r['method']:<4} median {r['median_mm']:.3f} "
            f"mean {r['mean_mm']:.3f} det {r['detection_rate']:.2f}"
        )
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 1, 5)
    args = a.parse_args()
    main(seed=args.seed, out=args.out)
