"""Figure 12 of the paper: Steger centres of both stripes on the image.

A rendered T-intersection in sunshine: the R−G image after MED (horizontal stripe: MED down
the columns, vertical stripe: MED along the rows) with the sub-pixel Steger centres drawn on
it, and a zoom on the weld bead where the ground truth is drawn too.

Writes `results/fig12_centres.png`.
"""

from __future__ import annotations

import numpy as np

from experiments import common as C  # noqa: E402


def main(seed: int = 7, nuisance: str = "sunny", kind: str = "cross", out: str = str(C.RESULTS)):
    """Draw Figure 12; return the error summary of each stripe."""
    import matplotlib.pyplot as plt

    from cslx.segmentation import centres_to_pixels, stripe_errors
    from cslx.segmentation.med import med
    from cslx.segmentation.steger import steger_centres
    from cslx.sensor import default_sensor

    sensor = default_sensor()
    image, gt = C.frame_at(kind, nuisance, seed, 0, sensor)
    I = C.mono(image, "r-g").astype(np.float32)
    outs, uvs, rows = {}, {}, []
    for stripe, axis in (("h", 0), ("v", 1)):
        B = np.asarray(med(I, axis=axis).output)
        outs[stripe] = B
        uvs[stripe] = centres_to_pixels(steger_centres(B, sigma=2.0, axis=axis), stripe)
        e = stripe_errors(uvs[stripe], gt[C.STRIPE_GT[stripe]], sensor, axis)
        rows.append(dict(stripe=stripe, **e))
    fig, axes = plt.subplots(1, 3, figsize=(17, 4.6), gridspec_kw=dict(width_ratios=[1, 1, 1]))
    both = np.maximum(
        outs["h"] / max(outs["h"].max(), 1e-9), outs["v"] / max(outs["v"].max(), 1e-9)
    )
    C.image_axis(axes[0], image, f"captured ({kind}, {nuisance}, seed {seed})")
    C.image_axis(
        axes[1],
        np.clip(both, 0, 1),
        "after MED (max of both directions) + Steger centres",
        cmap="gray",
    )
    C.draw_points(axes[1], uvs["h"], "cyan", 1.0)
    C.draw_points(axes[1], uvs["v"], "yellow", 1.0)
    # Zoom where the horizontal stripe crosses the bead: the largest row excursion.
    hv = gt["h_v"]
    u0 = int(np.nanargmin(hv)) if np.isfinite(hv).any() else 320
    v0 = float(np.nanmin(hv))
    ax = axes[2]
    ax.imshow(image, interpolation="nearest")
    ax.plot(np.arange(len(hv)), hv, color="magenta", lw=0.8, label="ground truth")
    C.draw_points(ax, uvs["h"], "cyan", 6, "Steger after MED (h)")
    ax.plot(gt["v_u"], np.arange(len(gt["v_u"])), color="magenta", lw=0.8)
    C.draw_points(ax, uvs["v"], "yellow", 6, "Steger after MED (v)")
    ax.set_xlim(u0 - 60, u0 + 60)
    ax.set_ylim(v0 + 45, v0 - 25)
    ax.set_title("zoom on the bead: centres vs ground truth", fontsize=9)
    ax.legend(fontsize=7, loc="lower left")
    for r in rows:
        name = "horizontal" if r["stripe"] == "h" else "vertical"
        axes[1].text(
            5,
            20 + 22 * (r["stripe"] == "v"),
            f"{name}: median {r['median_mm']:.3f} mm, detection {r['detection_rate']:.2f}",
            color="w",
            fontsize=8,
            bbox=dict(facecolor="k", alpha=0.5, lw=0),
        )
    fig.suptitle(
        "Figure 12: stripe centres (Steger's detector on the MED output, R−G)", fontsize=10
    )
    path = C.save_figure(fig, out, "fig12_centres.png")
    print(f"wrote {path}")
    for r in rows:
        print("  ", {k: (round(v, 4) if isinstance(v, float) else v) for k, v in r.items()})
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 1, 7)
    args = a.parse_args()
    main(seed=args.seed, out=args.out)
