"""Figure 18 of the paper: the stripes extracted under four conditions.

Four rendered frames: a T-intersection in sunshine, a straight weld in sunshine, strong
reflections (glare preset: white saturated glints on the bead) and a hard shadow, each with
the centres that the paper's method (R−G, MED, Steger) finds on both stripes drawn on it
(horizontal stripe cyan, vertical yellow) and its error summary.

Writes `results/fig18_conditions.png`.
"""

from __future__ import annotations

from experiments import common as C  # noqa: E402

PANELS = (
    ("cross", "sunny", "T-intersection in sunshine"),
    ("straight", "sunny", "straight weld in sunshine"),
    ("straight", "glare", "reflections / glare"),
    ("cross", "shadow", "shadow"),
)


def main(seed: int = 18, out: str = str(C.RESULTS)):
    """Draw Figure 18; return per panel and stripe the error summary."""
    import matplotlib.pyplot as plt

    from cslx.segmentation import stripe_errors
    from cslx.sensor import default_sensor

    sensor = default_sensor()
    fig, axes = plt.subplots(2, 4, figsize=(20, 8.2), gridspec_kw=dict(hspace=0.12, wspace=0.04))
    rows = []
    for k, (kind, nuisance, title) in enumerate(PANELS):
        image, gt = C.frame_at(kind, nuisance, seed, k, sensor)
        C.image_axis(axes[0, k], image, f"({'abcd'[k]}) {title}")
        ax = axes[1, k]
        C.image_axis(ax, image, None)
        text = []
        for stripe, colour in (("h", "cyan"), ("v", "yellow")):
            uv = C.centres_for(image, "med", C.SPACES["r-g"], stripe)
            C.draw_points(ax, uv, colour, 1.2)
            e = stripe_errors(uv, gt[C.STRIPE_GT[stripe]], sensor, C.STRIPE_PLANE[stripe])
            rows.append(dict(panel=title, kind=kind, nuisance=nuisance, stripe=stripe, **e))
            text.append(
                f"{stripe}: median {e['median_mm']:.2f} mm, det. {e['detection_rate']:.2f}, "
                f">1 mm {e['gross_outliers']}"
            )
        ax.set_title("MED + Steger (R−G): " + " | ".join(t.split(",")[0] for t in text), fontsize=8)
        ax.text(
            6,
            470,
            "\n".join(text),
            color="w",
            fontsize=7,
            va="bottom",
            bbox=dict(facecolor="k", alpha=0.55, lw=0),
        )
    fig.suptitle(
        f"Figure 18: frames under four conditions (seed {seed}) and the extracted stripes "
        "(cyan: horizontal, yellow: vertical)",
        fontsize=10,
    )
    path = C.save_figure(fig, out, "fig18_conditions.png")
    print(f"wrote {path}")
    for r in rows:
        print(
            f"  {r['panel']:<28} {r['stripe']} median {r['median_mm']:.3f} mean {r['mean_mm']:.3f} "
            f"det {r['detection_rate']:.2f} gross {r['gross_outliers']}"
        )
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 4, 18)
    args = a.parse_args()
    main(seed=args.seed, out=args.out)
