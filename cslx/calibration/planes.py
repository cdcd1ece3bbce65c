"""Laser-plane calibration (paper Figures 4–5): stripe points on the boards, lifted and fitted.

Stripe centres of the laser-on images that fall on the board are lifted to 3-D by
intersecting their rays with that pose's board plane; each laser plane
a x + b y + c z + 1 = 0 is fitted to its points by orthogonal least squares after a
least-median-of-squares start and iterative trimming of outliers.

Beyond the paper's cross: the number of laser lines (one line laser, or a cross) is found
from the images — each candidate stripe's plane must pass `PlaneGates` (RMS, inlier share,
points, views) or it is refused with the reason — and the laser images may be the plain
images themselves (the centres are taken inside the board's image only).
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ..sensor.camera import Camera, pixel_to_ray
from ..sensor.rig import CalibrationError, plane_angle_deg
from .camera import CameraCalibration, _project_view_jit
from .zhang import (
    rotation_to_rvec,
)


@dataclasses.dataclass(frozen=True)
class PlaneFit:
    """A plane a x + b y + c z + 1 = 0 fitted to 3-D points with outlier rejection.

    Attributes:
        plane: (3,) coefficients (a, b, c), camera frame, 1/mm.
        residuals: (M,) signed orthogonal distances of all points, mm.
        inliers: (M,) bool, the points kept by the trimming.
        rms: RMS orthogonal distance of the inliers, mm.
        covariance: (3, 3) covariance of (a, b, c) from σ² (JᵀJ)⁻¹ on the inliers.
    """

    plane: np.ndarray
    residuals: np.ndarray
    inliers: np.ndarray
    rms: float
    covariance: np.ndarray

    @property
    def std(self) -> np.ndarray:
        return np.sqrt(np.clip(np.diag(self.covariance), 0, None))


def _plane_from_points(P: np.ndarray) -> tuple[np.ndarray, np.ndarray, float]:
    """Total least squares: unit normal n, centroid c (n·X = n·c), and the flatness ratio."""
    c = P.mean(axis=0)
    _, s, vt = np.linalg.svd(P - c, full_matrices=False)
    return vt[-1], c, (s[1] / s[0] if s[0] > 0 else 0.0)


def _coefficients(n: np.ndarray, c: np.ndarray) -> np.ndarray:
    d = n @ c
    if abs(d) < 1e-9 * max(1.0, np.linalg.norm(c)):
        raise CalibrationError(
            "the fitted laser plane passes through the camera centre: it cannot be written "
            "a x + b y + c z + 1 = 0 (nor triangulate)"
        )
    return -n / d


def fit_plane(
    points: ArrayLike,
    *,
    trim: float = 3.0,
    n_trials: int = 300,
    seed: int = 0,
    min_points: int = 10,
) -> PlaneFit:
    """Fit a x + b y + c z + 1 = 0 to points by orthogonal least squares, robustly.

    The paper fits each laser plane "using a least square method" (section 2.3). Here the
    start is least median of squares over random point triples (no threshold to choose); then
    points farther than `trim` × σ (σ = 1.4826 × median absolute residual) are dropped and the
    plane refitted by total least squares until the inlier set stops changing.

    Args:
        points: (M, 3) camera-frame points, mm.
        trim: rejection threshold in robust standard deviations.
        n_trials: LMedS samples.
        seed: random seed of the sampling.
        min_points: fewer points raise `CalibrationError`.

    Raises:
        CalibrationError: too few points, points (nearly) collinear, or a plane through the
            camera centre.
    """
    P = np.asarray(points, np.float64)
    if P.ndim != 2 or P.shape[1] != 3:
        raise ValueError(f"points must be (M, 3), got shape {P.shape}")
    P = P[np.all(np.isfinite(P), axis=1)]
    M = len(P)
    if M < max(3, min_points):
        raise CalibrationError(f"too few stripe points to fit a laser plane: {M} < {min_points}")
    _, _, flat = _plane_from_points(P)
    if flat < 1e-3:
        raise CalibrationError(
            "the stripe points are (nearly) collinear: they come from one board pose or from "
            "boards that are nearly parallel at the same distance; use more varied poses"
        )
    rng = np.random.default_rng(seed)
    idx = rng.integers(0, M, size=(n_trials, 3))
    a, b, c = P[idx[:, 0]], P[idx[:, 1]], P[idx[:, 2]]
    nrm = np.cross(b - a, c - a)
    ln = np.linalg.norm(nrm, axis=1)
    ok = ln > 1e-12 * np.max(ln)
    nrm, a = nrm[ok] / ln[ok, None], a[ok]
    med = np.median(np.abs((P[None] - a[:, None]) @ nrm[..., None])[..., 0], axis=1)
    best = int(np.argmin(med))
    n, c0 = nrm[best], a[best]
    inl = np.ones(M, bool)
    for _ in range(30):
        r = (P - c0) @ n
        sigma = 1.4826 * np.median(np.abs(r - np.median(r[inl]))) + 1e-12
        new = np.abs(r) <= trim * sigma
        if new.sum() < 3:
            break
        n, c0, _ = _plane_from_points(P[new])
        if np.array_equal(new, inl):
            break
        inl = new
    plane = _coefficients(n, c0)
    nn = np.linalg.norm(plane)
    res = (P @ plane + 1) / nn
    # Jacobian of the orthogonal distance (n·X + 1)/‖n‖ with respect to n = (a, b, c).
    Pi = P[inl]
    J = Pi / nn - np.outer(Pi @ plane + 1, plane) / nn**3
    dof = max(int(inl.sum()) - 3, 1)
    s2 = float(np.sum(res[inl] ** 2) / dof)
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((3, 3), np.nan)
    return PlaneFit(
        plane=plane,
        residuals=res,
        inliers=inl,
        rms=float(np.sqrt(np.mean(res[inl] ** 2))),
        covariance=cov,
    )


_rays_jit = jax.jit(lambda uv, camera: pixel_to_ray(uv, camera, normalize=False))


def lift_to_board(
    uv: ArrayLike, camera: Camera, R: ArrayLike, t: ArrayLike
) -> tuple[np.ndarray, np.ndarray]:
    """Pixels → their rays ∩ the board plane of pose (R, t) (Figure 4's feature points).

    Returns:
        (X_c, X_t): (M, 3) camera-frame points and (M, 3) target-frame points (z_t ≈ 0).
    """
    uv = np.asarray(uv, np.float64).reshape(-1, 2)
    # Pad to a multiple of 512 points so that the compiled ray function is reused.
    m = len(uv)
    padded = np.zeros((max(512, -(-m // 512) * 512), 2))
    padded[:m] = uv
    padded[m:] = (float(camera.u0), float(camera.v0))
    with jax.enable_x64(True):
        ray = np.asarray(_rays_jit(jnp.asarray(padded), camera))[:m]
    R = np.asarray(R, np.float64)
    t = np.asarray(t, np.float64)
    n = R[:, 2]
    s = (n @ t) / (ray @ n)
    Xc = ray * s[:, None]
    Xt = (Xc - t) @ R
    return Xc, Xt


def board_mask(
    camera: Camera,
    R: ArrayLike,
    t: ArrayLike,
    pattern: tuple[int, int],
    square: float,
    extent: float = 1.0,
) -> np.ndarray:
    """(H, W) bool: the image of the board of pose (R, t).

    The region is the rectangle of the inner corners grown by `extent` squares on every side
    (1: the outer row of squares of a chessboard, which every chessboard has).
    """
    import cv2

    cols, rows = pattern
    w, h = camera.image_size
    s = np.linspace(0, 1, 40)
    e = extent * square
    x0, y0 = -e, -e
    X, Y = (cols - 1) * square + 2 * e, (rows - 1) * square + 2 * e
    border = np.concatenate(
        [
            np.stack([x0 + s * X, y0 + 0 * s], 1),
            np.stack([x0 + X + 0 * s, y0 + s * Y], 1),
            np.stack([x0 + (1 - s) * X, y0 + Y + 0 * s], 1),
            np.stack([x0 + 0 * s, y0 + (1 - s) * Y], 1),
        ]
    )
    obj = np.concatenate([border, np.zeros((len(border), 1))], axis=1)
    with jax.enable_x64(True):
        uv = np.asarray(
            _project_view_jit(
                jnp.asarray(rotation_to_rvec(jnp.asarray(R, jnp.float64))),
                jnp.asarray(t, jnp.float64),
                jnp.asarray(obj),
                camera,
            )
        )
    mask = np.zeros((h, w), np.uint8)
    cv2.fillPoly(mask, [np.round(uv).astype(np.int32)], 1)
    return mask.astype(bool)


def laser_centres(image_rgb, stripe, mask, method):
    """Stripe centres (pos, valid) inside `mask`: Steger ("auto", "steger", …) or "simple"."""
    if method == "auto":
        method = "steger"
    if method == "simple":
        from ._stripe import stripe_centres

        pos, valid, _ = stripe_centres(image_rgb, stripe, mask=mask)
        return np.asarray(pos, float), np.asarray(valid, bool)
    from ..segmentation import extract

    # Black outside the board: R − G is ≈ 0 on the grey board too, so the mask adds no edge,
    # and a stripe on the background cannot outshine the one on the board.
    masked = np.where(mask[..., None], np.asarray(image_rgb), 0).astype(np.uint8)
    c = extract(masked, method=method, space="r-g", stripe=stripe)
    return np.asarray(c.pos, float), np.asarray(c.valid, bool)


def on_board(
    Xt: np.ndarray, pattern: tuple[int, int], square: float, extent: float, margin: float
) -> np.ndarray:
    """(M,) bool: board-frame points within the board grown by `extent`, less `margin`."""
    cols, rows = pattern
    lo = (margin - extent) * square
    return (
        (Xt[:, 0] >= lo)
        & (Xt[:, 0] <= (cols - 1 + extent - margin) * square)
        & (Xt[:, 1] >= lo)
        & (Xt[:, 1] <= (rows - 1 + extent - margin) * square)
    )


def stripe_pixels(pos: np.ndarray, valid: np.ndarray, stripe: str) -> np.ndarray:
    """Per-column ("h") or per-row ("v") centres → (M, 2) pixels (u, v) of the valid ones."""
    idx = np.nonzero(valid)[0].astype(float)
    p = np.asarray(pos, float)[valid]
    return np.stack([idx, p], 1) if stripe == "h" else np.stack([p, idx], 1)


@dataclasses.dataclass(frozen=True)
class PlaneGates:
    """When a fitted laser plane is refused instead of written (never silently).

    A real line-laser plane fits to ≈ 0.1 mm RMS and a rendered one to ≈ 0.01–0.05 mm; a
    "plane" fitted to chessboard edges where there is no second line came out at 21 mm RMS
    with a third of its points rejected (issue 15). The gates sit far from both.

    Attributes:
        max_rms_mm: largest RMS orthogonal distance of the inliers, mm.
        min_inlier_share: smallest share of the stripe points the robust fit keeps.
        min_points: fewest inlier points over all views.
        min_views: fewest board poses that show the stripe (a plane needs two orientations).
        min_board_angle_deg: the boards that show a stripe must differ in orientation by at
            least this much, else the plane's tilt about the stripe is undetermined.
        same_line_deg: a second candidate plane within this angle of the first is the same
            line found by the other extractor, not a second line.
        min_support: a second line needs at least this share of the first line's inliers:
            a laser line crosses every board, so a few hundred stray centres beside a line of
            thousands are chessboard edges (rendered single-line boards give ≈ 0.1; the
            cross's two lines 0.4–0.9).
    """

    max_rms_mm: float = 0.5
    min_inlier_share: float = 0.7
    min_points: int = 50
    min_views: int = 2
    min_board_angle_deg: float = 2.0
    same_line_deg: float = 10.0
    min_support: float = 0.25


@dataclasses.dataclass(frozen=True)
class PlaneCalibration:
    """The laser planes found in laser-on images: one (a line laser) or two (a cross).

    Attributes:
        planes: (P, 3) coefficients a x + b y + c z + 1 = 0, camera frame; P = 1 or 2, the
            horizontal stripe's plane first.
        stripes: the stripe ("h"/"v") of each plane.
        fits: the P `PlaneFit`s (residuals, inliers, rms in mm, covariance).
        angle_deg: angle between the planes (NaN with one plane).
        points: per plane, the (M, 3) camera-frame stripe points on the boards.
        pixels: per plane, their (M, 2) pixels.
        views: per plane, the (M,) index of the view each point came from.
        counts: (F, 2) stripe points on the board per view for the candidate stripes
            (column 0: horizontal, 1: vertical; 0 where fewer than `min_points_per_view`).
        rejected: candidate stripe → why it is not a plane of this calibration.
    """

    planes: np.ndarray
    stripes: tuple[str, ...]
    fits: tuple[PlaneFit, ...]
    angle_deg: float
    points: tuple[np.ndarray, ...]
    pixels: tuple[np.ndarray, ...]
    views: tuple[np.ndarray, ...]
    counts: np.ndarray
    rejected: dict[str, str] = dataclasses.field(default_factory=dict)

    def summary(self) -> dict:
        """The per-plane report written as calibration-file extras (docs/contracts.md)."""
        return dict(
            plane_rms_mm=[f.rms for f in self.fits],
            plane_points=[int(f.inliers.sum()) for f in self.fits],
            plane_outliers=[int((~f.inliers).sum()) for f in self.fits],
            plane_inlier_share=[float(f.inliers.mean()) for f in self.fits],
            plane_std=[f.std.tolist() for f in self.fits],
            plane_covariance=[f.covariance.tolist() for f in self.fits],
            plane_views=[int(len(np.unique(v))) for v in self.views],
            lines_detected=list(self.stripes),
            rejected_lines=dict(self.rejected),
        )


_NAMES = {"h": "horizontal", "v": "vertical"}


def _read_rgb(image):
    import cv2

    if isinstance(image, str | os.PathLike):
        bgr = cv2.imread(os.fspath(image), cv2.IMREAD_COLOR)
        if bgr is None:
            raise FileNotFoundError(f"cannot read image {os.fspath(image)!r}")
        return cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
    return np.asarray(image)


def _candidate(stripe, pts, counts, normals, gates, seed, n_images):
    """Fit one candidate stripe's plane; (PlaneFit, None) or (None, why it is refused)."""
    name = f"{_NAMES[stripe]} line"
    k = "hv".index(stripe)
    used = np.nonzero(counts[:, k] >= 1)[0]
    per_image = counts[:, k].tolist()
    if len(used) < gates.min_views:
        return None, (
            f"{name}: on the board in {len(used)} of {n_images} laser images (points per "
            f"image: {per_image}); at least {gates.min_views} poses must show it on the board"
        )
    nu = normals[used]
    spread = float(np.degrees(np.arccos(np.clip(np.abs(nu @ nu.T), 0, 1).min())))
    if spread < gates.min_board_angle_deg:
        return None, (
            f"{name}: all boards that show it are nearly parallel (their normals are within "
            f"{spread:.2f}° < {gates.min_board_angle_deg}°): the plane's tilt about the line "
            "is undetermined; tilt the board between poses"
        )
    P = np.concatenate(pts[k])
    try:
        fit = fit_plane(P, seed=seed, min_points=gates.min_points)
    except CalibrationError as e:
        return None, f"{name}: {e}"
    n_in, share = int(fit.inliers.sum()), float(fit.inliers.mean())
    if fit.rms > gates.max_rms_mm or share < gates.min_inlier_share or n_in < gates.min_points:
        return fit, (
            f"{name}: poor plane fit (RMS {fit.rms:.3f} mm, limit {gates.max_rms_mm}; "
            f"{n_in} of {len(P)} points inliers = {share:.0%}, limit "
            f"{gates.min_inlier_share:.0%}; at least {gates.min_points} inliers): no such "
            "laser line on the boards, or its centres are unreliable"
        )
    return fit, None


def calibrate_planes(
    calib: CameraCalibration,
    laser_images: Sequence,
    pattern: tuple[int, int],
    square: float,
    *,
    method: str = "auto",
    lines: int | None = None,
    stripes: Sequence[str] = ("h", "v"),
    gates: PlaneGates | None = None,
    extent: float = 1.0,
    margin: float = 0.25,
    min_points_per_view: int = 10,
    seed: int = 0,
) -> PlaneCalibration:
    """Fit the laser planes from laser-on images of the calibrated board poses (Figs. 4–5).

    For each view i and each candidate stripe (horizontal: a centre per column; vertical: a
    centre per row): the stripe centres inside the board's image (so a laser image may be
    the very image the corners came from); their rays ∩ board plane i (the pose of `calib`);
    points off the board (`extent` squares around the inner corners, less a `margin`)
    dropped; then `fit_plane` per candidate over all views.

    How many lines: a candidate whose fit passes `gates` is a laser line; one that fails is
    reported in `rejected` with the reason (a line laser has no second line: its
    "horizontal" candidate is chessboard edges or the same line seen again, and is refused,
    never written). `lines` = None keeps every line found (at least one); `lines` = 2
    requires both (else `CalibrationError` naming the failing line); `lines` = 1 keeps the
    best one (most inliers).

    Args:
        calib: camera calibration whose view i shows the same pose as `laser_images[i]`.
        laser_images: (H, W, 3) uint8 RGB frames (or paths) with the laser on.
        pattern, square: the board (inner corners (cols, rows), square side).
        method: "simple" (`cslx.calibration._stripe`), a `cslx.segmentation.extract`
            method, or "auto" (Steger).
        lines: None (detect), 1 or 2.
        stripes: the candidate stripes ("h", "v").
        gates: when a plane is refused (`PlaneGates()` by default).
        extent: how far the board reaches beyond the inner corners, in squares (1: the
            outer row of squares; points beyond may fall off the board).
        margin: band inside that border to ignore, in squares.
        min_points_per_view: fewer points on a board do not count as a view of that stripe.
        seed: seed of the robust fit.

    Raises:
        CalibrationError: no laser line on the boards, fewer lines than `lines`, image and
            pose counts that differ; the message says which line failed and why.
    """
    gates = gates or PlaneGates()
    if lines not in (None, 1, 2):
        raise ValueError(f"lines must be None (detect), 1 or 2, got {lines!r}")
    stripes = tuple(stripes)
    if not stripes or any(s not in ("h", "v") for s in stripes):
        raise ValueError(f"stripes must be among 'h', 'v', got {stripes!r}")
    if lines is not None and lines > len(stripes):
        raise ValueError(f"lines={lines} but only {len(stripes)} candidate stripe(s)")
    if len(laser_images) != len(calib.rvecs):
        raise CalibrationError(
            f"{len(laser_images)} laser images for {len(calib.rvecs)} calibrated poses: "
            "each laser image must show the pose of the plain image with the same index"
        )
    Rs = calib.rotations
    pts, pix, views = ([], []), ([], []), ([], [])
    counts = np.zeros((len(laser_images), 2), int)
    for i, image in enumerate(laser_images):
        image = _read_rgb(image)
        mask = board_mask(calib.camera, Rs[i], calib.tvecs[i], pattern, square, extent)
        for stripe in stripes:
            k = "hv".index(stripe)
            pos, valid = laser_centres(image, stripe, mask, method)
            uv = stripe_pixels(pos, valid & np.isfinite(pos), stripe)
            if len(uv) == 0:
                continue
            Xc, Xt = lift_to_board(uv, calib.camera, Rs[i], calib.tvecs[i])
            keep = on_board(Xt, pattern, square, extent, margin)
            if int(keep.sum()) >= min_points_per_view:
                counts[i, k] = int(keep.sum())
                pts[k].append(Xc[keep])
                pix[k].append(uv[keep])
                views[k].append(np.full(int(keep.sum()), i))
    normals = Rs[:, :, 2]
    fits, rejected = {}, {}
    for stripe in stripes:
        fit, why = _candidate(stripe, pts, counts, normals, gates, seed, len(laser_images))
        if why is None:
            fits[stripe] = fit
        else:
            rejected[stripe] = why
    if len(fits) == 2:
        # The same line found by both extractors (a line at ≈ 45° in the image)?
        a, b = sorted(fits, key=lambda s: -int(fits[s].inliers.sum()))
        angle = plane_angle_deg(fits[a].plane, fits[b].plane)
        if angle < gates.same_line_deg:
            del fits[b]
            rejected[b] = (
                f"{_NAMES[b]} line: its plane is {angle:.1f}° from the {_NAMES[a]} line's "
                "(the same laser line found twice), not a second line"
            )
    if len(fits) == 2:
        a, b = sorted(fits, key=lambda s: -int(fits[s].inliers.sum()))
        n_a, n_b = int(fits[a].inliers.sum()), int(fits[b].inliers.sum())
        if n_b < gates.min_support * n_a:
            del fits[b]
            rejected[b] = (
                f"{_NAMES[b]} line: {n_b} inlier points against {n_a} of the {_NAMES[a]} line "
                f"(less than {gates.min_support:.0%}): stray centres, not a second laser line"
            )
    if lines == 1 and len(fits) == 2:
        a, b = sorted(fits, key=lambda s: -int(fits[s].inliers.sum()))
        del fits[b]
        rejected[b] = f"{_NAMES[b]} line: found, but --lines 1 keeps the line with most points"
    if not fits or (lines is not None and len(fits) < lines):
        want = "a laser line" if lines is None else f"{lines} laser line(s)"
        raise CalibrationError(
            f"found {len(fits)} laser line(s) on the boards, need {want}: "
            + "; ".join(rejected[s] for s in stripes if s in rejected)
        )
    kept = tuple(s for s in ("h", "v") if s in fits)
    ks = ["hv".index(s) for s in kept]
    planes = np.stack([fits[s].plane for s in kept])
    return PlaneCalibration(
        planes=planes,
        stripes=kept,
        fits=tuple(fits[s] for s in kept),
        angle_deg=plane_angle_deg(planes[0], planes[1]) if len(kept) == 2 else float("nan"),
        points=tuple(np.concatenate(pts[k]) for k in ks),
        pixels=tuple(np.concatenate(pix[k]) for k in ks),
        views=tuple(np.concatenate(views[k]) for k in ks),
        counts=counts,
        rejected=rejected,
    )


def edge_crossings(
    uv: ArrayLike, camera: Camera, R: ArrayLike, t: ArrayLike, square: float, stripe: str
) -> np.ndarray:
    """The paper's feature points (Figure 5): where a stripe crosses the squares' edges.

    The stripe pixels are lifted to the board of pose (R, t); the horizontal stripe ("h",
    ordered by u) is cut by the vertical edges x_t = k·square, the vertical stripe ("v",
    ordered by v) by the horizontal edges y_t = k·square. Crossings are linearly interpolated
    between the two neighbouring centres (one pixel apart).

    Returns:
        (K, 2) pixels of the crossings.
    """
    uv = np.asarray(uv, float)
    if len(uv) < 2:
        return np.zeros((0, 2))
    axis = 0 if stripe == "h" else 1
    order = np.argsort(uv[:, axis])
    uv = uv[order]
    _, Xt = lift_to_board(uv, camera, R, t)
    q = Xt[:, axis] / square
    out = []
    for j in range(len(uv) - 1):
        if abs(uv[j + 1, axis] - uv[j, axis]) > 1.5:
            continue  # a gap in the stripe: no interpolation across it
        lo, hi = np.floor(q[j]), np.floor(q[j + 1])
        if lo != hi:
            edge = max(lo, hi)
            w = (edge - q[j]) / (q[j + 1] - q[j])
            out.append(uv[j] + w * (uv[j + 1] - uv[j]))
    return np.asarray(out).reshape(-1, 2)
