"""Figure 21 of the paper: 3-D weld profiles from triangulated stripes, in the robot frame.

A straight weld and a T-intersection (rendered, sunny preset) are segmented with the
paper's method (R−G, MED, Steger); each stripe's centres are triangulated with
`cslx.sensor.triangulate(..., robot_frame=True)` (x_r forward, y_r left, z_r out of the
wall). The horizontal stripe gives the cross-section of the followed weld (z_r vs y_r); the
vertical stripe runs forward 40 mm beside it and shows the crossing weld's bead at a
T-intersection (z_r vs x_r). Ground truth is drawn in black.

Writes `results/fig21_weld_profiles.png`.
"""

from __future__ import annotations

import numpy as np

from experiments import common as C  # noqa: E402


def _limits(ax, x, z):
    """Zoom on the ground-truth profile (the wall is tilted and offset by the robot's pose)."""
    ok = np.isfinite(x) & np.isfinite(z)
    ax.set_xlim(np.max(x[ok]) + 2, np.min(x[ok]) - 2) if ax.xaxis_inverted() else ax.set_xlim(
        np.min(x[ok]) - 2, np.max(x[ok]) + 2
    )
    ax.set_ylim(np.min(z[ok]) - 1.5, np.max(z[ok]) + 2.5)


def main(seed: int = 21, nuisance: str = "sunny", out: str = str(C.RESULTS)):
    """Draw Figure 21; return per scene and stripe the error summary (mm, robot frame)."""
    import jax.numpy as jnp
    import matplotlib.pyplot as plt

    from cslx.sensor import default_sensor, triangulate

    sensor = default_sensor()
    fig = plt.figure(figsize=(18, 10))
    rows = []
    for r, kind in enumerate(("straight", "cross")):
        image, gt = C.frame_at(kind, nuisance, seed, r, sensor)
        ax3 = fig.add_subplot(2, 3, 3 * r + 1, projection="3d")
        pts = {}
        for stripe, colour in (("h", "tab:blue"), ("v", "tab:orange")):
            uv = C.centres_for(image, "med", C.SPACES["r-g"], stripe)
            ok = np.all(np.isfinite(uv), axis=1)
            plane = C.STRIPE_PLANE[stripe]
            X = np.array(
                triangulate(
                    sensor, jnp.asarray(np.where(ok[:, None], uv, 320.0)), plane, robot_frame=True
                )
            )
            X[~ok] = np.nan
            G = np.array(sensor.to_robot(jnp.asarray(np.nan_to_num(gt[C.STRIPE_GT[stripe]]))))
            G[~np.all(np.isfinite(gt[C.STRIPE_GT[stripe]]), axis=1)] = np.nan
            pts[stripe] = (X, G)
            ax3.plot(
                X[:, 0],
                X[:, 1],
                X[:, 2],
                ".",
                ms=1.5,
                color=colour,
                label=f"{'horizontal' if stripe == 'h' else 'vertical'} stripe",
            )
            ax3.plot(G[:, 0], G[:, 1], G[:, 2], "-", lw=0.6, color="k")
            d = np.linalg.norm(X - G, axis=1)
            d = d[np.isfinite(d)]
            rows.append(
                dict(
                    kind=kind,
                    stripe=stripe,
                    n=len(d),
                    median_mm=float(np.median(d)),
                    mean_mm=float(np.mean(d)),
                    p95_mm=float(np.percentile(d, 95)),
                    bead_width_mm=float(gt["bead_width_mm"]),
                    bead_height_mm=float(gt["bead_height_mm"]),
                )
            )
        gz = np.concatenate([pts["h"][1][:, 2], pts["v"][1][:, 2]])
        ax3.set_zlim(np.nanmin(gz) - 3, np.nanmax(gz) + 5)  # outliers beyond are clipped
        ax3.set_xlabel("x_r (mm)", fontsize=8)
        ax3.set_ylabel("y_r (mm)", fontsize=8)
        ax3.set_zlabel("z_r (mm)", fontsize=8)
        ax3.tick_params(labelsize=6)
        ax3.view_init(elev=28, azim=-125)
        ax3.set_title(
            f"{'straight weld' if kind == 'straight' else 'T-intersection'}: 3-D points "
            "(robot frame)",
            fontsize=9,
        )
        ax3.legend(fontsize=7, loc="upper left")
        Xh, Gh = pts["h"]
        ax = fig.add_subplot(2, 3, 3 * r + 2)
        ax.plot(Xh[:, 1], Xh[:, 2], ".", ms=2, color="tab:blue", label="MED + Steger (R−G)")
        ax.plot(Gh[:, 1], Gh[:, 2], "-", lw=0.8, color="k", label="ground truth")
        ax.invert_xaxis()  # y_r points left: draw as seen from behind the robot
        ax.set_xlabel("y_r (mm, left ←)", fontsize=8)
        ax.set_ylabel("z_r (mm)", fontsize=8)
        _limits(ax, Gh[:, 1], Gh[:, 2])
        ax.set_title(
            f"horizontal stripe: cross-section of the followed weld "
            f"(w {float(gt['bead_width_mm']):.1f} mm, h {float(gt['bead_height_mm']):.1f} mm)",
            fontsize=9,
        )
        ax.legend(fontsize=7)
        ax.tick_params(labelsize=7)
        Xv, Gv = pts["v"]
        ax = fig.add_subplot(2, 3, 3 * r + 3)
        ax.plot(Xv[:, 0], Xv[:, 2], ".", ms=2, color="tab:orange", label="MED + Steger (R−G)")
        ax.plot(Gv[:, 0], Gv[:, 2], "-", lw=0.8, color="k", label="ground truth")
        ax.set_xlabel("x_r (mm, forward)", fontsize=8)
        ax.set_ylabel("z_r (mm)", fontsize=8)
        _limits(ax, Gv[:, 0], Gv[:, 2])
        ax.set_title(
            "vertical stripe (40 mm right of the weld): "
            + ("crossing weld's bead" if kind == "cross" else "plain wall"),
            fontsize=9,
        )
        ax.legend(fontsize=7)
        ax.tick_params(labelsize=7)
    fig.suptitle(
        f"Figure 21: weld profiles from the triangulated stripes ({nuisance} preset, seed "
        f"{seed}); points beyond the plotted range are gross errors",
        fontsize=10,
    )
    fig.tight_layout()
    path = C.save_figure(fig, out, "fig21_weld_profiles.png")
    print(f"wrote {path}")
    for r in rows:
        print("  ", {k: (round(v, 3) if isinstance(v, float) else v) for k, v in r.items()})
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 2, 21)
    args = a.parse_args()
    main(seed=args.seed, out=args.out)
