"""The baselines of Table 6: centre of mass (CM) and split-and-merge LA / QA / AA.

All work on one monochrome frame and return the `Centres` of `steger` (one centre per
column for a horizontal stripe, `axis=0`; per row for a vertical stripe, `axis=1`), so that
experiments can loop over methods. They are NumPy/SciPy: split-and-merge is sequential by
nature (docs/corrections.md; Usamentiaga et al. 2012).

- **CM**: in each column, the centre of mass of the intensity above a threshold, in a
  window around the column's maximum.
- **LA / QA / AA**: after Usamentiaga, Molleda and García, "Fast and robust laser stripe
  extraction for 3D reconstruction in industrial environments", Machine Vision and
  Applications 23 (2012). Per-column peak points with a sub-pixel peak estimate (three-point
  Gaussian fit, parabola where the fit is undefined) are grouped into runs of neighbouring
  columns, then split where the approximation error exceeds a threshold (at the worst
  point), adjacent segments merged where their union is still approximated within the
  threshold, and short segments dropped. The output is the fitted function evaluated at
  every column spanned by a kept segment (short gaps inside a segment are filled). The
  approximating function is a least-squares line (LA), a least-squares quadratic (QA), or an
  Akima spline (AA, `scipy.interpolate.Akima1DInterpolator`) through knots that are the
  medians of consecutive blocks of `knot_spacing` points (an Akima spline through every point
  would interpolate the noise and never exceed any threshold). This is cslx's reading of the
  2012 paper, whose exact peak detector and spline knots are not restated in Zhang et al.

Background and strength: a column's background is its median; its strength is the peak
height above that background. Columns whose strength is below `min_peak` × the frame's
largest strength (and below `min_height`, absolute) have no peak.
"""

from __future__ import annotations

import numpy as np
from numpy.typing import ArrayLike

from .steger import Centres

__all__ = ["cm", "la", "qa", "aa", "column_peaks", "split_and_merge"]


def _columns(image: ArrayLike, axis: int) -> np.ndarray:
    """The frame with the search direction first: (rows searched, lines) float64."""
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (horizontal stripe) or 1 (vertical), got {axis!r}")
    image = np.asarray(image)
    if image.ndim != 2:
        raise ValueError(f"expected a 2-D monochrome image (H, W), got shape {image.shape}")
    image = image.astype(np.float64)
    return image if axis == 0 else image.T


def _centres(pos: np.ndarray, valid: np.ndarray, strength: np.ndarray) -> Centres:
    return Centres(np.where(valid, pos, np.nan), valid.astype(bool), np.where(valid, strength, 0.0))


def _peak_heights(cols: np.ndarray, min_peak: float, min_height: float):
    """Per-line argmax, peak height above the median background, and the keep mask."""
    peak = np.argmax(cols, axis=0)
    lines = np.arange(cols.shape[1])
    background = np.median(cols, axis=0)
    height = cols[peak, lines] - background
    top = height.max() if height.size else 0.0
    keep = (height > 0) & (height >= min_peak * top) & (height >= min_height)
    return peak, background, height, keep


def cm(
    image: ArrayLike,
    axis: int = 0,
    *,
    window: int = 7,
    threshold: float = 0.5,
    min_peak: float = 0.1,
    min_height: float = 0.0,
) -> Centres:
    """Centre of mass of the intensity above a threshold around each column's maximum.

    Args:
        image: (H, W) monochrome frame.
        axis: 0 for a horizontal stripe (one centre per column), 1 for a vertical one (per row).
        window: half-width of the window around the maximum, pixels (rows v−window..v+window).
        threshold: intensities count above background + threshold × (peak − background),
            i.e. a fraction of the column's peak height in [0, 1).
        min_peak: a column has no centre when its peak height is below this fraction of the
            frame's largest peak height.
        min_height: absolute floor on the peak height (intensity units).

    Returns:
        `Centres`; `strength` is the peak height above the column's median.
    """
    cols = _columns(image, axis)
    m, n = cols.shape
    peak, background, height, keep = _peak_heights(cols, min_peak, min_height)
    offsets = np.arange(-window, window + 1)
    rows = peak[None, :] + offsets[:, None]
    inside = (rows >= 0) & (rows < m)
    values = np.take_along_axis(cols, np.clip(rows, 0, m - 1), axis=0)
    level = background + threshold * height
    weight = np.where(inside, np.maximum(values - level[None, :], 0.0), 0.0)
    mass = weight.sum(axis=0)
    valid = keep & (mass > 0)
    pos = (weight * rows).sum(axis=0) / np.where(mass > 0, mass, 1.0)
    return _centres(pos, valid, height)


def column_peaks(
    image: ArrayLike, axis: int = 0, *, min_peak: float = 0.1, min_height: float = 0.0
) -> Centres:
    """Per-column peak with a three-point Gaussian sub-pixel estimate (parabola as fallback).

    The Gaussian fit through (p−1, p, p+1) above the median background puts the peak at
    p + (ln a − ln c) / (2 (ln a − 2 ln b + ln c)); where a side value is not positive the
    parabola p + (a − c) / (2 (a − 2b + c)) is used. Same arguments as `cm`.
    """
    cols = _columns(image, axis)
    m, n = cols.shape
    peak, background, height, keep = _peak_heights(cols, min_peak, min_height)
    lines = np.arange(n)
    a = cols[np.clip(peak - 1, 0, m - 1), lines] - background
    b = cols[peak, lines] - background
    c = cols[np.clip(peak + 1, 0, m - 1), lines] - background
    with np.errstate(divide="ignore", invalid="ignore"):
        positive = (a > 0) & (b > 0) & (c > 0)
        la_, lb, lc = (np.log(np.where(positive, x, 1.0)) for x in (a, b, c))
        den_g = la_ - 2 * lb + lc
        den_p = a - 2 * b + c
        gauss = np.where(den_g < 0, (la_ - lc) / (2 * np.where(den_g < 0, den_g, -1.0)), 0.0)
        parab = np.where(den_p < 0, (a - c) / (2 * np.where(den_p < 0, den_p, -1.0)), 0.0)
    delta = np.clip(np.where(positive, gauss, parab), -0.5, 0.5)
    interior = (peak > 0) & (peak < m - 1)
    delta = np.where(interior, delta, 0.0)
    return _centres(peak + delta, keep, height)


def _fitter(kind: str, knot_spacing: int):
    """Return fit(x, y) -> callable approximation for the segment's points."""

    def poly(x, y, degree):
        degree = min(degree, len(x) - 1)
        x0 = x.mean()
        coef = np.polyfit(x - x0, y, degree)
        return lambda q: np.polyval(coef, np.asarray(q, float) - x0)

    def akima(x, y):
        # Imported here: scipy.interpolate costs ≈ 0.5 s of every start-up that imports
        # cslx.segmentation (the tracker's too), and only AA needs it.
        from scipy.interpolate import Akima1DInterpolator

        k = max(len(x) // knot_spacing, 1)
        if k < 3:
            return poly(x, y, 2 if k == 2 else 1)
        blocks = np.array_split(np.arange(len(x)), k)
        kx = np.array([np.median(x[b]) for b in blocks])
        ky = np.array([np.median(y[b]) for b in blocks])
        spline = Akima1DInterpolator(kx, ky, extrapolate=True)
        return lambda q: spline(np.asarray(q, float))

    if kind == "linear":
        return lambda x, y: poly(x, y, 1)
    if kind == "quadratic":
        return lambda x, y: poly(x, y, 2)
    if kind == "akima":
        return akima
    raise ValueError(f"kind must be 'linear', 'quadratic' or 'akima', got {kind!r}")


def split_and_merge(
    x: np.ndarray,
    y: np.ndarray,
    kind: str,
    *,
    tolerance: float = 1.0,
    min_length: int = 10,
    max_gap: int = 5,
    max_jump: float = 3.0,
    knot_spacing: int = 16,
) -> list[tuple[int, int, object]]:
    """Split-and-merge approximation of points (x sorted, integer) by segments of one kind.

    Args:
        x: (K,) increasing integer column indices of the peak points.
        y: (K,) sub-pixel peak rows.
        kind: "linear", "quadratic" or "akima".
        tolerance: largest allowed |y − f(x)| of a segment's points, pixels.
        min_length: segments with fewer points are dropped.
        max_gap: neighbouring points more than this many columns apart start a new run.
        max_jump: neighbouring points whose rows differ by more start a new run, pixels.
        knot_spacing: points per Akima knot (AA only).

    Returns:
        [(first_point, end_point, f)]: kept segments as index ranges into x, y with their
        fitted function.
    """
    fit = _fitter(kind, knot_spacing)
    if len(x) == 0:
        return []
    breaks = np.flatnonzero((np.diff(x) > max_gap) | (np.abs(np.diff(y)) > max_jump)) + 1
    bounds = np.concatenate([[0], breaks, [len(x)]])
    runs = [(int(a), int(b)) for a, b in zip(bounds[:-1], bounds[1:], strict=True)]

    def error(a, b):
        f = fit(x[a:b], y[a:b])
        r = np.abs(y[a:b] - f(x[a:b]))
        return f, r

    # Split: every segment is approximated within the tolerance or is a single point.
    done, stack = [], runs[::-1]
    while stack:
        a, b = stack.pop()
        if b - a <= 2:
            done.append((a, b))
            continue
        _, r = error(a, b)
        worst = int(np.argmax(r))
        if r[worst] <= tolerance:
            done.append((a, b))
            continue
        # Split at the worst point; it starts the right part (or ends the left one at the end).
        k = a + max(worst, 1)
        stack.extend([(k, b), (a, k)])
    done.sort()

    # Merge adjacent segments (within max_gap) whose union still fits the tolerance.
    merged = True
    while merged and len(done) > 1:
        merged = False
        out = [done[0]]
        for a, b in done[1:]:
            pa, pb = out[-1]
            if x[a] - x[pb - 1] <= max_gap and abs(y[a] - y[pb - 1]) <= max_jump:
                _, r = error(pa, b)
                if r.max() <= tolerance:
                    out[-1] = (pa, b)
                    merged = True
                    continue
            out.append((a, b))
        done = out

    return [(a, b, error(a, b)[0]) for a, b in done if b - a >= min_length]


def _approximate(
    image,
    axis,
    kind,
    *,
    tolerance,
    min_length,
    max_gap,
    max_jump,
    knot_spacing,
    min_peak,
    min_height,
) -> Centres:
    peaks = column_peaks(image, axis, min_peak=min_peak, min_height=min_height)
    n = len(peaks.pos)
    x = np.flatnonzero(peaks.valid)
    y = np.asarray(peaks.pos)[x]
    pos = np.full(n, np.nan)
    segments = split_and_merge(
        x,
        y,
        kind,
        tolerance=tolerance,
        min_length=min_length,
        max_gap=max_gap,
        max_jump=max_jump,
        knot_spacing=knot_spacing,
    )
    for a, b, f in segments:
        cols = np.arange(x[a], x[b - 1] + 1)
        pos[cols] = f(cols)
    valid = np.isfinite(pos)
    return _centres(pos, valid, np.asarray(peaks.strength))


_DOC = """Split-and-merge stripe centres approximated by {what} (Usamentiaga et al. 2012, {name}).

    Args:
        image: (H, W) monochrome frame.
        axis: 0 for a horizontal stripe (one centre per column), 1 for a vertical one (per row).
        tolerance: split where a segment's approximation error exceeds this, pixels (1.0).
        min_length: drop segments with fewer peak points (10).
        max_gap: peak points more than this many columns apart start a new segment (5).
        max_jump: neighbouring peak points further apart in v start a new segment, px (3.0).
        knot_spacing: peak points per Akima knot, AA only (16).
        min_peak, min_height: relative and absolute peak-height floors, as in `cm`.

    Returns:
        `Centres`: the fitted function at every column spanned by a kept segment; `strength`
        is the column's peak height above its median (0 where not valid).
    """


def _method(kind: str, name: str, what: str):
    def method(
        image: ArrayLike,
        axis: int = 0,
        *,
        tolerance: float = 1.0,
        min_length: int = 10,
        max_gap: int = 5,
        max_jump: float = 3.0,
        knot_spacing: int = 16,
        min_peak: float = 0.1,
        min_height: float = 0.0,
    ) -> Centres:
        return _approximate(
            image,
            axis,
            kind,
            tolerance=tolerance,
            min_length=min_length,
            max_gap=max_gap,
            max_jump=max_jump,
            knot_spacing=knot_spacing,
            min_peak=min_peak,
            min_height=min_height,
        )

    method.__name__ = method.__qualname__ = name.lower()
    method.__doc__ = _DOC.format(what=what, name=name)
    return method


la = _method("linear", "LA", "least-squares lines")
qa = _method("quadratic", "QA", "least-squares quadratics")
aa = _method("akima", "AA", "Akima splines")
