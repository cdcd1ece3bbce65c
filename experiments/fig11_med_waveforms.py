"""Figure 11 of the paper: column waveforms before and after MED, all columns superposed.

The monochrome (R−G) frame's columns are drawn on top of each other, before MED and after it
(delay-compensated output of `med.med`, horizontal stripe, the paper's L = 50 %): MED
concentrates each column's energy at the stripe. The panels on the right show the
normalised columns around the true stripe row, to compare widths. Kurtosis (mean sample
excess kurtosis of the columns) is given before and after.

Writes `results/fig11_med_waveforms.png`.
"""

from __future__ import annotations

import numpy as np

from experiments import common as C  # noqa: E402


def _excess_kurtosis(X: np.ndarray) -> float:
    Xc = X - X.mean(0)
    m2 = (Xc**2).mean(0)
    m4 = (Xc**4).mean(0)
    return float(np.mean(m4 / np.maximum(m2, 1e-12) ** 2 - 3.0))


def _width(X: np.ndarray, rows: np.ndarray) -> float:
    """Median over columns of the full width at half maximum around the true row (px)."""
    widths = []
    for j in range(X.shape[1]):
        if not np.isfinite(rows[j]):
            continue
        c = X[:, j] - np.median(X[:, j])
        i0 = int(round(rows[j]))
        if not 3 <= i0 < len(c) - 3:
            continue
        peak = c[i0 - 2 : i0 + 3].max()
        if peak <= 0:
            continue
        lo = i0
        while lo > 0 and c[lo] > peak / 2:
            lo -= 1
        hi = i0
        while hi < len(c) - 1 and c[hi] > peak / 2:
            hi += 1
        widths.append(hi - lo - 1)
    return float(np.median(widths)) if widths else float("nan")


def main(
    seeds=(7, 11), nuisances=("sunny", "glare"), kind: str = "straight", out: str = str(C.RESULTS)
):
    """Draw Figure 11 for each (nuisance, seed); return kurtosis and width before/after MED."""
    import matplotlib.pyplot as plt

    from cslx.segmentation.med import med

    fig, axes = plt.subplots(
        len(nuisances),
        3,
        figsize=(15, 3.6 * len(nuisances)),
        gridspec_kw=dict(width_ratios=[2, 2, 1.2]),
    )
    axes = np.atleast_2d(axes)
    rows = []
    for r, (nuisance, seed) in enumerate(zip(nuisances, seeds, strict=True)):
        image, gt = C.frame_at(kind, nuisance, seed, 0)
        I = C.mono(image, "r-g").astype(np.float32)
        res = med(I, axis=0)
        B = np.asarray(res.output)
        k_in, k_out = _excess_kurtosis(I), _excess_kurtosis(B)
        w_in, w_out = _width(I, gt["h_v"]), _width(B, gt["h_v"])
        v = np.arange(I.shape[0])
        for ax, X, name, k in (
            (axes[r, 0], I, "before MED (R−G)", k_in),
            (axes[r, 1], B, "after MED", k_out),
        ):
            ax.plot(v, X, color="k", lw=0.3, alpha=0.05)
            ax.set_title(
                f"{nuisance}: {name}, all {X.shape[1]} columns; kurtosis {k:.1f}", fontsize=9
            )
            ax.set_xlabel("row v (px)", fontsize=8)
            ax.set_xlim(0, len(v) - 1)
            ax.tick_params(labelsize=7)
        ax = axes[r, 2]
        off = np.arange(-25, 26)
        for X, colour, name in ((I, "tab:blue", "before"), (B, "tab:red", "after")):
            prof = []
            for j in range(X.shape[1]):
                t = gt["h_v"][j]
                if not np.isfinite(t) or not 30 <= t < X.shape[0] - 30:
                    continue
                c = np.interp(t + off, v, X[:, j])
                c = c - np.median(X[:, j])
                prof.append(c / max(np.abs(c).max(), 1e-9))
            prof = np.asarray(prof)
            ax.plot(off, np.median(prof, 0), color=colour, lw=1.5, label=f"{name} MED")
            ax.fill_between(off, *np.percentile(prof, [10, 90], 0), color=colour, alpha=0.2)
        ax.axvline(0, color="k", lw=0.5, ls=":")
        ax.set_title(
            f"columns aligned on the true row (median, 10–90 %)\n"
            f"FWHM {w_in:.0f} px → {w_out:.0f} px",
            fontsize=8,
        )
        ax.set_xlabel("v − v_true (px)", fontsize=8)
        ax.legend(fontsize=7)
        ax.tick_params(labelsize=7)
        rows.append(
            dict(
                nuisance=nuisance,
                kind=kind,
                seed=seed,
                kurtosis_before=k_in,
                kurtosis_after=k_out,
                fwhm_before_px=w_in,
                fwhm_after_px=w_out,
                med_steps=int(res.steps),
                med_converged=bool(res.converged),
                med_delay_px=float(res.delay),
                filter_length=int(res.filter.shape[0]),
            )
        )
    fig.suptitle(
        "Figure 11: energy concentration by MED (horizontal stripe, R−G, L = 240)", fontsize=10
    )
    fig.tight_layout()
    path = C.save_figure(fig, out, "fig11_med_waveforms.png")
    print(f"wrote {path}")
    for r in rows:
        print("  ", r)
    return rows


if __name__ == "__main__":
    a = C.parser(__doc__, 1, 7)
    args = a.parse_args()
    main(seeds=(args.seed, args.seed + 4), out=args.out)
