"""The weld's heading from the vertical stripe's heights in one frame (host NumPy).

Where the vertical stripe crosses the followed bead's flank, one frame sees the weld's
heading (`cslx.runtime.weld`'s module docstring, "Heading"); moved out of
`cslx.runtime.weld` (600-line limit) and re-exported there.
"""

from __future__ import annotations

__all__ = ["heading_from_vertical"]


def heading_from_vertical(
    points_h,
    points_v,
    bead_y_mm: float,
    bead_width_mm: float,
    x_ref: float,
    *,
    max_deg: float = 12.0,
    step_deg: float = 0.1,
    trim_mm: float = 0.3,
    min_informative: int = 15,
) -> tuple[float, float]:
    """The weld's heading from the vertical stripe's heights, in one frame (cslx's own).

    The horizontal stripe crosses the followed bead at x_ref and gives its cross-section:
    heights above the plate T(y) along y_r (the template; plate = its points farther than
    0.6 w + 2 mm from the bead centre, a least-squares line; resampled every 0.25 mm and
    averaged over 2 mm, as its noise would bias θ). The vertical stripe runs along
    x_r and meets the same bead at lateral positions that change with the heading θ: a
    point (x, y) of the wall is at height T(y − tan θ · (x − x_ref)) above the plate. For
    each θ of a grid (±`max_deg`, `step_deg`) the vertical stripe's heights above the
    horizontal stripe's plate are compared with that prediction after a free offset and
    pitch along x_r (a + c (x − x_ref), least squares: the robot may be pitched on the wall);
    the cost is the truncated square (at `trim_mm`, so the crossing weld of a T and stray
    points do not count). θ̂ is the grid minimum refined by a parabola.

    Where the vertical stripe lies along the crown of a centred weld only |θ| is seen, and
    on bare plate nothing: the estimate is NaN when fewer than `min_informative` vertical
    points sit where the template has slope, or when the mirrored heading explains the
    heights almost as well (cost difference below 10 noise variances).

    Args:
        points_h: (W, 3) robot-frame points of the horizontal stripe (NaN = invalid).
        points_v: (H, 3) of the vertical stripe.
        bead_y_mm, bead_width_mm: the followed bead on the horizontal stripe.
        x_ref: x_r of the horizontal stripe on the plate (unused beyond a sanity check: the
            template is referred to the x_r where the stripe actually crosses the bead).
    Returns:
        (heading in degrees, CCW +, and its standard deviation in degrees), NaN if unseen.
    """
    import numpy as np

    nan = (float("nan"), float("nan"))
    ph = np.asarray(points_h, float)
    pv = np.asarray(points_v, float)
    if not (np.isfinite(bead_y_mm) and np.isfinite(bead_width_mm) and np.isfinite(x_ref)):
        return nan
    ph = ph[np.all(np.isfinite(ph), 1)]
    pv = pv[np.all(np.isfinite(pv), 1)]
    if len(ph) < 30 or len(pv) < 30:
        return nan
    yh, zh = ph[:, 1], ph[:, 2]
    plate = np.abs(yh - bead_y_mm) > 0.6 * bead_width_mm + 2.0
    if plate.sum() < 10:
        return nan
    b, a = np.polyfit(yh[plate], zh[plate], 1)
    # the template lies where the horizontal stripe crosses the bead (its x_r moves with
    # the surface height in the laser plane), not exactly at x_ref
    x_h = float(np.median(ph[~plate, 0]))
    order = np.argsort(yh)
    ys, hs = yh[order], (zh - (a + b * yh))[order]
    hs = np.where(np.abs(ys - bead_y_mm) > 0.6 * bead_width_mm + 2.0, 0.0, hs)
    # the template's noise biases θ: resample it every 0.25 mm and average over 2 mm
    grid_y = np.arange(ys[0], ys[-1], 0.25)
    if len(grid_y) < 16:
        return nan
    kernel = np.ones(9) / 9.0
    hs = np.convolve(np.interp(grid_y, ys, hs), kernel, mode="same")
    ys = grid_y
    X = pv[:, 0] - x_h
    Hv = pv[:, 2] - (a + b * pv[:, 1])
    grid = np.radians(np.arange(-max_deg, max_deg + 0.5 * step_deg, step_deg))
    U = pv[None, :, 1] - np.tan(grid)[:, None] * X[None, :]
    P = np.interp(U, ys, hs, left=0.0, right=0.0)
    R0 = Hv[None, :] - P
    w = np.ones_like(R0)
    for _ in range(3):
        S0, S1, S2 = w.sum(1), (w * X).sum(1), (w * X * X).sum(1)
        Sr, Sxr = (w * R0).sum(1), (w * X * R0).sum(1)
        det = np.maximum(S0 * S2 - S1 * S1, 1e-9)
        off = (S2 * Sr - S1 * Sxr) / det
        pitch = (S0 * Sxr - S1 * Sr) / det
        r = R0 - off[:, None] - pitch[:, None] * X[None, :]
        w = (np.abs(r) < trim_mm).astype(float)
    J = np.minimum(r * r, trim_mm**2).sum(1)
    k = int(np.argmin(J))
    inside = (np.abs(r[k]) < trim_mm).sum()
    s2 = max(J[k] / max(inside - 3, 1), 0.02**2)
    slope = 0.5 * np.abs(
        np.interp(U[k] + 1.0, ys, hs, left=0.0, right=0.0)
        - np.interp(U[k] - 1.0, ys, hs, left=0.0, right=0.0)
    )
    informative = int(((slope > 0.03) & (np.abs(r[k]) < trim_mm)).sum())
    if informative < min_informative or k in (0, len(grid) - 1):
        return nan
    mirror = int(np.argmin(np.abs(grid + grid[k])))
    far = np.abs(grid - grid[k]) > np.radians(1.0)
    if far[mirror] and J[mirror] - J[k] < 10 * s2:
        return nan
    # parabola through the minimum and its neighbours; variance 2 s² / J''
    j0, j1, j2 = J[k - 1], J[k], J[k + 1]
    h = grid[1] - grid[0]
    curv = (j0 - 2 * j1 + j2) / (h * h)
    shift = 0.5 * (j0 - j2) / (j0 - 2 * j1 + j2) if curv > 0 else 0.0
    theta = grid[k] + float(np.clip(shift, -1, 1)) * h
    sd = np.sqrt(2 * s2 / curv) if curv > 0 else np.inf
    return float(np.degrees(theta)), float(max(np.degrees(sd), step_deg))
