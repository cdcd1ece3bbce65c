"""Laser-plane calibration (paper Figures 4–5): stripe points on the boards, lifted and fitted.

Stripe centres of the laser-on images that fall on the board are lifted to 3-D by
intersecting their rays with that pose's board plane; each laser plane
a x + b y + c z + 1 = 0 is fitted to its points by orthogonal least squares after a
least-median-of-squares start and iterative trimming of outliers.
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
class PlaneCalibration:
    """Both laser planes from laser-on images (plane 0: horizontal stripe, 1: vertical).

    Attributes:
        planes: (2, 3) coefficients a x + b y + c z + 1 = 0, camera frame.
        fits: the two `PlaneFit`s (residuals, inliers, rms in mm, covariance).
        angle_deg: angle between the planes.
        points: per plane, the (M, 3) camera-frame stripe points on the boards.
        pixels: per plane, their (M, 2) pixels.
        views: per plane, the (M,) index of the view each point came from.
        counts: (F, 2) stripe points kept on the board per view and plane.
    """

    planes: np.ndarray
    fits: tuple[PlaneFit, PlaneFit]
    angle_deg: float
    points: tuple[np.ndarray, np.ndarray]
    pixels: tuple[np.ndarray, np.ndarray]
    views: tuple[np.ndarray, np.ndarray]
    counts: np.ndarray


def calibrate_planes(
    calib: CameraCalibration,
    laser_images: Sequence,
    pattern: tuple[int, int],
    square: float,
    *,
    method: str = "auto",
    extent: float = 1.0,
    margin: float = 0.25,
    min_points_per_view: int = 10,
    min_board_angle_deg: float = 2.0,
    seed: int = 0,
) -> PlaneCalibration:
    """Fit both laser planes from laser-on images of the calibrated board poses (Figs. 4–5).

    For each view i: stripe centres (per column for the horizontal stripe, per row for the
    vertical one) inside the board's image; their rays ∩ board plane i (the pose of
    `calib`); points off the board (`extent` squares around the inner corners, less a
    `margin`) dropped;
    then `fit_plane` per stripe over all views.

    Args:
        calib: camera calibration whose view i shows the same pose as `laser_images[i]`.
        laser_images: (H, W, 3) uint8 RGB frames (or paths) with the laser on.
        pattern, square: the board (inner corners (cols, rows), square side).
        method: "simple" (`cslx.calibration._stripe`), a `cslx.segmentation.extract` method,
            or "auto".
        extent: how far the board reaches beyond the inner corners, in squares (1: the
            outer row of squares; points beyond may fall off the board).
        margin: band inside that border to ignore, in squares.
        min_points_per_view: fewer points on a board do not count as a view of that stripe.
        min_board_angle_deg: the boards that see a stripe must differ in orientation by at
            least this much, else the plane's tilt about the stripe is undetermined.
        seed: seed of the robust fit.

    Raises:
        CalibrationError: a stripe not on the board in at least two views, all boards nearly
            parallel, too few stripe points, or a degenerate plane; the message says which.
    """
    import cv2

    if len(laser_images) != len(calib.rvecs):
        raise CalibrationError(
            f"{len(laser_images)} laser images for {len(calib.rvecs)} calibrated poses: "
            "each laser image must show the pose of the plain image with the same index"
        )
    cols, rows = pattern
    Rs = calib.rotations
    pts, pix, views = ([], []), ([], []), ([], [])
    counts = np.zeros((len(laser_images), 2), int)
    for i, image in enumerate(laser_images):
        if isinstance(image, str | os.PathLike):
            bgr = cv2.imread(os.fspath(image), cv2.IMREAD_COLOR)
            if bgr is None:
                raise FileNotFoundError(f"cannot read image {os.fspath(image)!r}")
            image = cv2.cvtColor(bgr, cv2.COLOR_BGR2RGB)
        mask = board_mask(calib.camera, Rs[i], calib.tvecs[i], pattern, square, extent)
        for k, stripe in enumerate("hv"):
            pos, valid = laser_centres(image, stripe, mask, method)
            uv = stripe_pixels(pos, valid & np.isfinite(pos), stripe)
            if len(uv) == 0:
                continue
            Xc, Xt = lift_to_board(uv, calib.camera, Rs[i], calib.tvecs[i])
            keep = on_board(Xt, pattern, square, extent, margin)
            counts[i, k] = int(keep.sum())
            if counts[i, k] >= min_points_per_view:
                pts[k].append(Xc[keep])
                pix[k].append(uv[keep])
                views[k].append(np.full(int(keep.sum()), i))
    normals = Rs[:, :, 2]
    fits = []
    for k, stripe in enumerate(("horizontal", "vertical")):
        used = np.nonzero(counts[:, k] >= min_points_per_view)[0]
        if len(used) < 2:
            raise CalibrationError(
                f"the {stripe} stripe (plane {k}) is on the board in {len(used)} of "
                f"{len(laser_images)} laser images (points per image: {counts[:, k].tolist()}); "
                "at least two poses must show it on the board"
            )
        nu = normals[used]
        cosines = np.clip(np.abs(nu @ nu.T), 0, 1)
        spread = float(np.degrees(np.arccos(cosines.min())))
        if spread < min_board_angle_deg:
            raise CalibrationError(
                f"all boards that show the {stripe} stripe are nearly parallel (their normals "
                f"are within {spread:.2f}° < {min_board_angle_deg}°): the plane's tilt about "
                "the stripe is undetermined; tilt the board between poses"
            )
        fits.append(fit_plane(np.concatenate(pts[k]), seed=seed))
    planes = np.stack([f.plane for f in fits])
    return PlaneCalibration(
        planes=planes,
        fits=(fits[0], fits[1]),
        angle_deg=plane_angle_deg(planes[0], planes[1]),
        points=(np.concatenate(pts[0]), np.concatenate(pts[1])),
        pixels=(np.concatenate(pix[0]), np.concatenate(pix[1])),
        views=(np.concatenate(views[0]), np.concatenate(views[1])),
        counts=counts,
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
