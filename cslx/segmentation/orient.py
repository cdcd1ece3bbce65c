"""A stripe turned far from its search axis: smooth and link along it (issue 11, roll 45°).

The linked detector's first pass (`cslx.segmentation.ridges`, column profiles) smooths the
image by `SIGMA_ALONG` (6 px) along the image axis and links one candidate per column with a
free slope of 1 px per column (`LinkParams.slope`). A cross turned by ≈ 45° about the camera
axis breaks both: each column's profile of a stripe of slope m is smeared by ≈ 6 |m| px, and
the two stripes (slopes ≈ +1.05 and −1.19 rows per column at 45°: angles 46.5° and −50° on
the fresh frames 7700–7705) both cost the path almost nothing, so it follows one stripe up
to the crossing and the other after it (roll 45°, seeds 7700–7701, frames 0–1: p95 86–160
mm, 18–73 % gross centres, 397–526 false positives a stripe).

`search_slope` measures the stripe's direction: the image (search orientation, the stripe
one centre per column) is averaged in 4 × 4 blocks, its Hessian at σ `HESSIAN_SIGMA` (in
blocks) gives each line-like pixel (λ_min < 0, |λ_min| > 2 |λ_max|) a direction θ =
½ atan2(2 h_uv, h_uu − h_vv) (the eigenvector of the larger eigenvalue) and a weight
λ_min², summed in 1° bins and smoothed circularly (σ 2°). Of the peaks holding at least
`PEAK_SHARE` of the largest, the one nearest the search axis is this stripe (the other
stripe of the cross is the one nearer the other axis: the naming of `extract`'s "h" / "v");
its angle θ is refined by the bins' mean within ±3°. Where the histogram holds one peak
only (the other stripe too faint for it), that peak can be the other stripe: one at least
45° − `SINGLE_BAND_DEG` from the axis whose sign is not this search's (the tie's rule,
`peak_angles`; beyond 45° nearness says the same),
or ≥ 20° from the calibration's angle, is taken as the other stripe and this one as
perpendicular to it (or at the calibration's angle); before, both searches took the same
stripe (roll45/shadow, development seed 7809 frame 0: the vertical stripe washed out in the
sunlit half, its search on the horizontal stripe, 324 gross centres, 131 false ones; after,
99.69 % of its rows, 0 gross, median 0.026 mm). Where |θ| ≥ `MIN_DEG` the first pass
then runs along it (`slope` = tan θ): `smooth_along` smooths by `SIGMA_ALONG` along the line
(1, m) instead of the axis (linear interpolation across), and the Viterbi links the
candidates' offsets from that line (`ridges._linked(slope=...)`), so the stripe is flat to
the path and the other stripe steep. Below `MIN_DEG` nothing changes (bit for bit).

Evidence: the module docstring of `experiments/ood_extraction.py`.

Pure JAX (the histogram) and NumPy on its 180 bins.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np
from jax import lax

from .steger import _filter_axis, _taps

__all__ = [
    "MIN_DEG",
    "PEAK_SHARE",
    "direction_histogram",
    "drop_other",
    "peak_angles",
    "plane_angle",
    "search_slope",
    "stripe_angle",
    "smooth_along",
]

#: A stripe whose direction is at least this far (degrees) from its search axis is smoothed
#: and linked along it.
MIN_DEG = 25.0
#: Peaks of the direction histogram below this share of the largest are not stripes.
PEAK_SHARE = 0.25
#: Scale (in 4 × 4 blocks) of the Hessian that measures the directions.
HESSIAN_SIGMA = 1.0
#: Block size of the average taken before the Hessian.
BLOCK = 4
#: Largest |slope| `smooth_along` accepts (the padding is static): 60°.
MAX_SLOPE = math.tan(math.radians(60.0))


@jax.jit
def direction_histogram(img):
    """(180,) weights of line directions θ = −90 … 89° (1° bins) in `img` (H, W); θ is the
    angle of the line to axis 1 (the search orientation's "along"), positive towards +axis 0."""
    h, w = (img.shape[0] // BLOCK) * BLOCK, (img.shape[1] // BLOCK) * BLOCK
    small = img[:h, :w].reshape(h // BLOCK, BLOCK, w // BLOCK, BLOCK).mean((1, 3))
    s = HESSIAN_SIGMA
    a0, a1, a2 = _filter_axis(small, s, (0, 1, 2), 0)  # along axis 0 (v)
    hvv = _filter_axis(a2, s, (0,), 1)[0]
    huv = _filter_axis(a1, s, (1,), 1)[0]
    huu = _filter_axis(a0, s, (2,), 1)[0]
    half, diff = 0.5 * (huu + hvv), jnp.sqrt(0.25 * (huu - hvv) ** 2 + huv**2)
    lmin, lmax = half - diff, half + diff
    line = (lmin < 0) & (-lmin > 2 * jnp.abs(lmax))
    theta = 0.5 * jnp.degrees(jnp.arctan2(2 * huv, huu - hvv))  # along the line, (−90, 90]
    idx = jnp.floor(theta + 90.0).astype(jnp.int32) % 180
    weight = jnp.where(line, lmin**2, 0.0)
    return jax.ops.segment_sum(weight.reshape(-1), idx.reshape(-1), 180)


def search_slope(
    img, prefer: int = 1, expected: float | None = None
) -> tuple[float | None, float | None]:
    """(slope, other): the slope (px across per px along) of this stripe in `img` (search
    orientation: axis 1 along, axis 0 across), None where it is within `MIN_DEG` of the
    axis or no peak is found; and the slope of the strongest other peak (the other stripe of
    the cross), None where there is none. Which peak is this stripe: `peak_angles`
    (`prefer`: +1 for "h", −1 for "v"; `expected`: the calibration's angle, `plane_angle`)."""
    hist = np.asarray(direction_histogram(img), float)
    angle, other = peak_angles(hist, prefer, expected)
    if angle is None or abs(angle) < MIN_DEG:
        return None, None
    slopes = [None if a is None else math.tan(math.radians(a)) for a in (angle, other)]
    return float(np.clip(slopes[0], -MAX_SLOPE, MAX_SLOPE)), slopes[1]


#: Two peaks whose distances to the search axis differ by less than this (degrees) are a
#: tie (`peak_angles`): a cross turned by ≈ ±45°. The h and v searches measure a stripe's
#: angle alike to ≈ 0.01° (rig "roll-45", seed 7590, frames 0–1: h −41.10 / 43.53°, v
#: −48.90 / 46.47° from the y axis); the rigs' own separations: 2.7° (roll −45°: −41.1 and
#: 43.5°), 3.5° (roll +45°: 46.5 and −50°), both kept by nearness.
TIE_DEG = 1.0
#: A single significant peak (the other stripe dark to the histogram) is the other stripe
#: where it lies at least 45° − `SINGLE_BAND_DEG` from the axis with the other sign than
#: `prefer` (the tie's rule), or ≥ 20° from the calibration's angle; this stripe is then
#: taken perpendicular to it (or at the calibration's angle), the peak as the other
#: (`SINGLE_OTHER`; module docstring).
SINGLE_BAND_DEG = 5.0
SINGLE_OTHER = True


def peak_angles(
    hist: np.ndarray, prefer: int = 1, expected: float | None = None
) -> tuple[float | None, float | None]:
    """The angles (degrees) of this stripe's significant peak and of the strongest other
    peak at least 20° from it (module docstring); None where absent.

    Which stripe is "h" (laser plane 0) and which "v" (docs/contracts.md, "Stripes"): with
    the calibration's `expected` angle (`plane_angle`, the stripe of that plane on a wall
    facing the camera), the peak nearest it. Without: the peak nearest the search axis (h:
    the stripe nearer the image's x axis, v: the one nearer its y axis); where two peaks'
    distances to the axis differ by less than `TIE_DEG` and both are at least `MIN_DEG` (a
    cross turned by ≈ ±45°, where that nearness is noise), the one whose angle has the sign
    `prefer` (+1 for "h", −1 for "v"). "h" is then the stripe that falls to the right in
    the image (v grows with u) and "v" the one that rises, in both searches (a stripe at
    +45° from the x axis is at +45° from the y axis in the transposed search, one at −45°
    at −45°), so the two are never the same stripe. That is the plane order of a projector
    turned by +45° (`cslx.sensor.rig.cross_projector_planes(roll_deg=45)`); one turned by
    −45° needs the calibration (`cslx extract --calib` passes it). A single peak of the
    other stripe (`SINGLE_OTHER`) gives this stripe's angle as perpendicular to it (or the
    calibration's) and the peak as the other."""
    k = np.arange(-6, 7)
    g = np.exp(-0.5 * (k / 2.0) ** 2)
    smooth = sum(gi * np.roll(hist, -ki) for ki, gi in zip(k, g, strict=True))
    top = smooth.max()
    if not top > 0:
        return None, None
    peaks = (smooth >= np.roll(smooth, 1)) & (smooth > np.roll(smooth, -1))
    peaks &= smooth >= PEAK_SHARE * top
    angles = np.arange(180) - 89.5  # bin centres
    cand = np.flatnonzero(peaks)
    if cand.size == 0:
        return None, None
    fine = np.array([_refine(hist, angles, c) for c in cand])
    if expected is not None:
        i = cand[np.argmin(np.abs((fine - expected + 90) % 180 - 90))]
    else:
        i = cand[np.argmin(np.abs(angles[cand]))]
        dist = np.abs(fine)
        tie = (dist >= MIN_DEG) & (dist <= dist[cand == i][0] + TIE_DEG)
        mine = tie & (np.sign(fine) == prefer)
        if dist[cand == i][0] >= MIN_DEG and mine.any() and (tie & ~mine).any():
            i = cand[mine][np.argmin(dist[mine])]
    far = cand[np.abs((angles[cand] - angles[i] + 90) % 180 - 90) >= 20]
    j = far[np.argmax(smooth[far])] if far.size else None
    fi = _refine(hist, angles, i)
    if j is None and SINGLE_OTHER:  # one stripe seen: is it this one or the other?
        if expected is not None:
            if abs((fi - expected + 90) % 180 - 90) >= 20:
                return float(expected), fi
        elif abs(fi) >= 45.0 - SINGLE_BAND_DEG and np.sign(fi) != prefer:
            return fi - math.copysign(90.0, fi), fi
    return fi, None if j is None else _refine(hist, angles, j)


def plane_angle(plane, fx: float, fy: float, axis: int) -> float:
    """The search-orientation angle (degrees, `direction_histogram`'s convention) of the
    stripe of laser `plane` (a, b, c: a x + b y + c z + 1 = 0, camera frame) on a wall
    facing the camera: there a x_n + b y_n = const in normalised coordinates (any depth), so
    in pixels the stripe runs along (b / fy, −a / fx); lens distortion is left out. `axis`
    0 for "h" (the angle to the image x axis), 1 for "v" (to the y axis, transposed)."""
    a, b = float(plane[0]), float(plane[1])
    phi = math.degrees(math.atan2(-a / fx, b / fy))  # from x, positive towards +v
    theta = phi if axis == 0 else 90.0 - phi
    return (theta + 90.0) % 180.0 - 90.0


def stripe_angle(sensor, stripe: str) -> float:
    """`plane_angle` of a two-plane calibration's stripe "h" (plane 0) or "v" (plane 1)."""
    axis = 0 if stripe == "h" else 1
    cam = sensor.camera
    return plane_angle(np.asarray(sensor.planes)[axis], float(cam.fx), float(cam.fy), axis)


def _refine(hist, angles, i) -> float:
    """A peak's angle: the histogram's mean within ±3 bins of bin i."""
    offs = np.arange(-3, 4)
    wts = hist[(i + offs) % 180]
    return float(angles[i] + (wts @ offs) / wts.sum()) if wts.sum() > 0 else float(angles[i])


#: `drop_other`: pieces of the path split by gaps of at least `PIECE_GAP` centres; pieces
#: shorter than `PIECE_MIN` are left to `ridges.drop_stray`.
PIECE_GAP = 4
PIECE_MIN = 12


def drop_other(pos, valid, slope: float, other: float | None) -> np.ndarray:
    """`valid` without the pieces of the path that run along the other stripe.

    Linked by offsets from this stripe's line (`ridges._linked(slope=...)`), the other
    stripe of a cross turned ≈ 45° has a relative slope d = other − slope of only ≈ 1.8–2.2
    px per centre, which the path's smoothness cost (β (|Δ| − 1)² ≈ 0.3–0.7) lets the
    reward of a strong stripe pay for: where this stripe ends (leaves the frame or the fan
    ends), the path continued along the other one across a gap (roll 45° saturated,
    vertical stripe, fresh seeds 7700–7701: 103–114 false centres a frame). A piece (split
    by gaps ≥ `PIECE_GAP`, at least `PIECE_MIN` centres) whose least-squares relative slope
    b lies nearer d than 0 is dropped."""
    pos, valid = np.asarray(pos, float), np.asarray(valid, bool).copy()
    if other is None:
        return valid
    d = other - slope
    j = np.flatnonzero(valid)
    if j.size == 0:
        return valid
    cuts = np.flatnonzero(np.diff(j) > PIECE_GAP)
    for piece in np.split(j, cuts + 1):
        if piece.size < PIECE_MIN:
            continue
        b = np.polyfit(piece, pos[piece] - slope * piece, 1)[0]
        if abs(b - d) < abs(b):
            valid[piece] = False
    return valid


#: `trim_ends`: an end of the path is cut where its strength falls below `END_SHARE` of the
#: median strength of the `END_PLATEAU` centres that follow the first `END_SKIP` inside it.
END_SHARE = 0.5
END_SKIP = 12
END_PLATEAU = 40
#: Cut an end within `BORDER_ALONG` centres of the frame's end along too (True: the earlier
#: behaviour). There a slanted stripe's first-pass strength falls to 0.43–0.44 of the plateau
#: and the cut lost 4–9 rows an end. Not cutting (`experiments.roll_losses --trial`,
#: development seeds 7800–7809, frames 0–3): V detection 99.54 → 99.66 %, no gross centre
#: added, V median / p95 0.0317 / 0.175 → 0.0319 / 0.178 mm (roll45/glare V p95 0.145 →
#: 0.173) and H medians moved (roll35/saturated 0.0343 → 0.0319). Held out once (fresh seeds
#: 7905–7909, one per nuisance, rolls 35° and 45°, frames 0–3, 40 frames): V detection
#: 99.25 → 99.29 % (roll35/clean 99.83 → 100, roll45/clean 99.48 → 99.63, roll45/sunny
#: 99.92 → 100), gross 4 → 4, false centres 2 → 1, V median 0.0302 → 0.0302 and p95 0.143 →
#: 0.142 mm, H identical; no condition-stripe worse. So the end at the frame's border stays.
#: Only turned stripes (``slope``) are trimmed: the benchmark's rig does not reach here.
TRIM_AT_BORDER = False
BORDER_ALONG = 3


def trim_ends(valid, strength) -> np.ndarray:
    """`valid` without the path's tails past the stripe's ends (half the plateau strength).

    Smoothed along the stripe by a Gaussian (σ_along), a fan's end inside the frame becomes
    an erf ramp of the ridge strength along the path: half the plateau at the end, ≈ 4 % two
    σ_along past it, still a rewarded candidate. So the path ran on past the end along the
    line (roll 45° clean, seed 7701 frame 0, horizontal stripe: 14 columns past the end at
    column 94). Each end of the path is cut back to the first centre whose strength reaches
    `END_SHARE` × the median strength of the centres `END_SKIP` to `END_SKIP` +
    `END_PLATEAU` inside it. A stripe leaving the frame along the search axis keeps its
    strength to the border (the smoothing mirrors the image there) and is not cut."""
    valid = np.asarray(valid, bool).copy()
    z = np.asarray(strength, float)
    for order in (slice(None), slice(None, None, -1)):
        idx = np.flatnonzero(valid[order])
        if idx.size < END_SKIP + END_PLATEAU:
            continue
        if not TRIM_AT_BORDER and idx[0] < BORDER_ALONG:
            continue  # the path reaches the frame's end along: no fan's end to cut
        zz = z[order][idx]
        plateau = np.median(zz[END_SKIP : END_SKIP + END_PLATEAU])
        strong = np.flatnonzero(zz[:END_SKIP] >= END_SHARE * plateau)
        cut = strong[0] if strong.size else END_SKIP
        valid[order][idx[:cut]] = False
    return valid


@functools.partial(jax.jit, static_argnames=("sigma",))
def smooth_along(x, slope, *, sigma: float):
    """out[u, v] = Σ_k g(k) x[u + k, v + slope · k]: a Gaussian (σ `sigma`) along the line
    of `slope` through every pixel of `x` (W, H) — axis 0 along, axis 1 across, the
    transposed layout of `ridges._candidates_column`. Symmetric padding along (as
    `steger._filter_axis`), edge values across; linear interpolation across."""
    taps = _taps(sigma, 0)
    r = len(taps) - 1
    big = int(math.ceil(MAX_SLOPE * r)) + 2
    n, m = x.shape
    xp = jnp.pad(jnp.pad(x, ((r, r), (0, 0)), mode="symmetric"), ((0, 0), (big, big)), mode="edge")
    slope = jnp.clip(slope, -MAX_SLOPE, MAX_SLOPE).astype(x.dtype)
    out = jnp.zeros_like(x)
    for k in range(-r, r + 1):
        d = slope * k
        i = jnp.floor(d)
        f = d - i
        rows = lax.slice_in_dim(xp, r + k, r + k + n, axis=0)
        win = lax.dynamic_slice_in_dim(rows, big + i.astype(jnp.int32), m + 1, axis=1)
        out = out + float(taps[abs(k)]) * ((1 - f) * win[:, :m] + f * win[:, 1:])
    return out
