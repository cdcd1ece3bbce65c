"""Calibration of the cross structured-light sensor (paper section 2.3, results in 4.1).

Three steps, as the paper describes them, with the corrections of DESIGN.md:

1. **Camera** (Zhang 2000, eqs. (5)–(7)): chessboard corners by OpenCV with a 5×5 sub-pixel
   window; a closed-form start from normalised DLT homographies (V b = 0 by SVD, K from the
   image of the absolute conic, poses with the rotation made orthonormal); then one joint
   maximum-likelihood refinement of (fx, fy, u0, v0, k1, k2, p1, p2) and every board pose
   (rotation vectors) by Levenberg–Marquardt (optimistix, Cholesky normal equations, float64).
   The distortion is OpenCV's Brown–Conrady model (correction 1 of eq. (4)), so the result is
   the minimiser of the same objective as `cv2.calibrateCamera(flags=CALIB_FIX_K3)`.
2. **Laser planes** (Figures 4–5): stripe centres of the laser-on images that fall on the
   board are lifted to 3-D by intersecting their rays with that pose's board plane; each laser
   plane a x + b y + c z + 1 = 0 is fitted to its points by least squares (orthogonal
   distances) after a least-median-of-squares start and iterative trimming of outliers.
3. **Robot frame**: a rigid fit (Kabsch, no scale, det R = +1) of known target points.

Beyond the paper: parameter standard deviations from the Jacobian at the solution, a plane
covariance, and `refine_sensor`, a joint refinement of the camera, the poses and both planes
from the corners and the stripe points together, with an optional orthogonality constraint.
"""

from __future__ import annotations

import dataclasses
import os
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float

from ._calib_zhang import (
    homography,
    intrinsics_from_homographies,
    pose_from_homography,
    rodrigues,
    rotation_to_rvec,
)
from .camera import Camera, _undistort_step, distort, pixel_to_ray
from .sensor import CalibrationError, plane_angle_deg

__all__ = [
    "CameraCalibration",
    "PlaneFit",
    "board_points",
    "board_planes",
    "calibrate_camera",
    "detect_corners",
    "fit_plane",
    "fit_rigid",
    "JointCalibration",
    "refine_sensor",
    "PlaneCalibration",
    "board_mask",
    "calibrate_planes",
    "edge_crossings",
    "lift_to_board",
    "on_board",
    "stripe_pixels",
    "rodrigues",
    "rotation_to_rvec",
    "zhang_init",
]

#: The sub-pixel refinement of `reference.json` (OpenCV's winSize is the half size: 5 → 11×11
#: search window; the issue's "5×5 window" is this half size, the value OpenCV's samples use).
SUBPIX_WIN = (5, 5)
SUBPIX_CRITERIA = (3, 30, 0.1)  # cv2.TERM_CRITERIA_EPS + cv2.TERM_CRITERIA_COUNT, 30, 0.1

_INTRINSIC_NAMES = ("fx", "fy", "u0", "v0", "k1", "k2", "p1", "p2")


# ----------------------------------------------------------------------------- corners


def board_points(pattern: tuple[int, int], square: float) -> np.ndarray:
    """Target-frame corners (N, 3) in OpenCV's order: point c + cols·r is (c·s, r·s, 0).

    Args:
        pattern: inner corners (cols, rows), as `cv2.findChessboardCorners` takes them.
        square: side of a square (mm, or any unit: the poses come out in it).
    """
    cols, rows = pattern
    c, r = np.meshgrid(np.arange(cols), np.arange(rows))
    return np.stack([c.ravel() * square, r.ravel() * square, np.zeros(cols * rows)], axis=1)


def _read_gray(image) -> np.ndarray:
    import cv2

    if isinstance(image, str | os.PathLike):
        img = cv2.imread(os.fspath(image), cv2.IMREAD_GRAYSCALE)
        if img is None:
            raise FileNotFoundError(f"cannot read image {os.fspath(image)!r}")
        return img
    img = np.asarray(image)
    if img.ndim == 3 and img.shape[2] == 3:
        img = cv2.cvtColor(np.ascontiguousarray(img), cv2.COLOR_RGB2GRAY)
    if img.ndim != 2:
        raise ValueError(f"an image must be (H, W) or (H, W, 3), got shape {img.shape}")
    if img.dtype != np.uint8:
        raise ValueError(f"images must be uint8, got {img.dtype}")
    return img


def detect_corners(
    images: Sequence, pattern: tuple[int, int], names: Sequence[str] | None = None
) -> tuple[list[np.ndarray | None], list[str]]:
    """Find chessboard corners with sub-pixel accuracy in each image.

    `cv2.findChessboardCorners`, then `cv2.cornerSubPix(win=(5, 5), zeroZone=(-1, -1),
    criteria=(EPS+COUNT, 30, 0.1))`, exactly the method of `tests/data/opencv-samples/
    reference.json`.

    Args:
        images: file paths, or uint8 arrays (H, W) or RGB (H, W, 3).
        pattern: inner corners (cols, rows).
        names: labels for the skipped list (default: the paths, or "image <i>").

    Returns:
        (corners, skipped): per image an (N, 2) float64 array of pixels in OpenCV's order, or
        None where the board was not found; and the names of the images without a board.
    """
    import cv2

    pattern = (int(pattern[0]), int(pattern[1]))
    out, skipped = [], []
    for i, image in enumerate(images):
        if names is not None:
            name = names[i]
        elif isinstance(image, str | os.PathLike):
            name = os.fspath(image)
        else:
            name = f"image {i}"
        gray = _read_gray(image)
        found, corners = cv2.findChessboardCorners(gray, pattern)
        if not found:
            out.append(None)
            skipped.append(name)
            continue
        corners = cv2.cornerSubPix(gray, corners, SUBPIX_WIN, (-1, -1), SUBPIX_CRITERIA)
        out.append(corners.reshape(-1, 2).astype(np.float64))
    return out, skipped


# ----------------------------------------------------------------------------- packing


def _pack(image_points, object_points) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Views of unequal length → padded (F, N, 2), (F, N, 3) and a 0/1 mask (F, N)."""
    if len(image_points) == 0:
        raise CalibrationError("no views to calibrate from")
    imgs = [np.asarray(p, np.float64) for p in image_points]
    if isinstance(object_points, list | tuple):
        objs = [np.asarray(o, np.float64) for o in object_points]
        if len(objs) != len(imgs):
            raise ValueError(f"{len(imgs)} image point sets but {len(objs)} object point sets")
    else:
        objs = [np.asarray(object_points, np.float64)] * len(imgs)
    n = max(len(p) for p in imgs)
    F = len(imgs)
    img = np.zeros((F, n, 2))
    obj = np.zeros((F, n, 3))
    mask = np.zeros((F, n))
    for f, (p, o) in enumerate(zip(imgs, objs, strict=True)):
        if p.ndim != 2 or p.shape[1] != 2:
            raise ValueError(f"view {f}: image points must be (N, 2), got {p.shape}")
        if o.shape != (len(p), 3):
            raise ValueError(f"view {f}: object points must be ({len(p)}, 3), got {o.shape}")
        if not np.allclose(o[:, 2], 0):
            raise CalibrationError(f"view {f}: the target must be planar (z = 0)")
        if len(p) < 4:
            raise CalibrationError(f"view {f}: {len(p)} points; a homography needs at least 4")
        img[f, : len(p)] = p
        obj[f, : len(p)] = o
        mask[f, : len(p)] = 1
    # Padding copies the first point so that no division by zero occurs in masked terms.
    for f, p in enumerate(imgs):
        img[f, len(p) :] = img[f, 0]
        obj[f, len(p) :] = obj[f, 0]
    return img, obj, mask


# ----------------------------------------------------------------------------- Zhang


def zhang_init(
    image_points, object_points, image_size: tuple[int, int]
) -> tuple[Camera, np.ndarray, np.ndarray]:
    """Zhang's closed-form initialisation: intrinsics (zero distortion) and every pose.

    Args:
        image_points: per view (N_i, 2) pixels.
        object_points: (N, 3) target points (z = 0), or one (N_i, 3) array per view.
        image_size: (width, height).

    Returns:
        (camera, rvecs (F, 3), tvecs (F, 3)) in float64.
    """
    img, obj, mask = _pack(image_points, object_points)
    if len(img) < 2:
        raise CalibrationError("Zhang's method needs at least two views of the board")
    with jax.enable_x64(True):
        K, rvecs, tvecs = _init_jit(
            jnp.asarray(img), jnp.asarray(obj), jnp.asarray(mask), tuple(image_size)
        )
        K = np.asarray(K)
        if not np.all(np.isfinite(K)) or K[0, 0] <= 0 or K[1, 1] <= 0:
            raise CalibrationError(
                "the closed-form initialisation failed (no real solution of V b = 0): the "
                "board views are too similar (nearly parallel boards, or too few views)"
            )
        cam = Camera.from_matrix(jnp.asarray(K), jnp.zeros(4), tuple(image_size))
        return cam, np.asarray(rvecs), np.asarray(tvecs)


def _init_impl(img, obj, mask, image_size):
    Hs = jax.vmap(homography)(obj[..., :2], img, mask)
    K = intrinsics_from_homographies(Hs, image_size)
    rvecs, tvecs = jax.vmap(pose_from_homography, in_axes=(None, 0))(K, Hs)
    return K, rvecs, tvecs


_init_jit = jax.jit(_init_impl, static_argnums=3)


# ----------------------------------------------------------------------------- refinement


def _unpack(p: Float[Array, " P"], F: int, image_size) -> tuple[Camera, Array, Array]:
    cam = Camera(p[0], p[1], p[2], p[3], p[4:8], image_size)
    rvecs = p[8 : 8 + 3 * F].reshape(F, 3)
    tvecs = p[8 + 3 * F :].reshape(F, 3)
    return cam, rvecs, tvecs


def _project_view(
    rvec: Float[Array, 3], tvec: Float[Array, 3], obj: Float[Array, "n 3"], cam: Camera
) -> Float[Array, "n 2"]:
    """Target points → distorted pixels for one pose (eq. (5) with correction 1)."""
    Xc = obj @ rodrigues(rvec).T + tvec
    z = Xc[:, 2:]
    xy = Xc[:, :2] / jnp.where(z == 0, 1.0, z)
    xd = distort(xy, cam.dist)
    return jnp.stack([cam.fx * xd[:, 0] + cam.u0, cam.fy * xd[:, 1] + cam.v0], axis=-1)


_project_view_jit = jax.jit(_project_view)


def _reprojection(p, args):
    """Pixel residuals (F·N·2,) of all corners; padding rows are zero."""
    img, obj, mask, image_size = args
    cam, rvecs, tvecs = _unpack(p, img.shape[0], image_size)
    uv = jax.vmap(_project_view, in_axes=(0, 0, 0, None))(rvecs, tvecs, obj, cam)
    return ((uv - img) * mask[..., None]).ravel()


def _scaled(fn):
    """Residuals in scaled parameters y = p / s (s = 1 / column norms of J at the start).

    optimistix's Levenberg–Marquardt damps with λ I; pixels per unit focal length and per unit
    rotation differ by ~10³, so unscaled damping would crawl. Scaling makes every column of J
    unit length at the start (MINPACK's `diag`), which leaves the minimiser unchanged.
    """

    def scaled(y, args):
        data, s = args
        return fn(y * s, data)

    return scaled


def _refine_impl(p0, img, obj, mask, image_size, rtol, atol, max_steps):
    data = (img, obj, mask, image_size)
    J0 = jax.jacfwd(_reprojection)(p0, data)
    s = 1.0 / jnp.maximum(jnp.linalg.norm(J0, axis=0), 1e-12)
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    sol = optx.least_squares(
        _scaled(_reprojection),
        solver,
        p0 / s,
        args=(data, s),
        max_steps=max_steps,
        throw=False,
    )
    p = sol.value * s
    r = _reprojection(p, data)
    J = jax.jacfwd(_reprojection)(p, data)
    return p, r, J, sol.result == optx.RESULTS.successful, sol.stats["num_steps"]


_refine_jit = jax.jit(_refine_impl, static_argnums=(4, 7))


@dataclasses.dataclass(frozen=True)
class CameraCalibration:
    """Result of `calibrate_camera`.

    Attributes:
        camera: refined intrinsics and (k1, k2, p1, p2), float64.
        rvecs, tvecs: (F, 3) board poses (target → camera: X_c = R(rvec) X_t + t), in the
            unit of the object points.
        rms: RMS reprojection error, px, OpenCV's definition sqrt(SSR / N_points).
        per_image_rms: (F,) RMS per view, px.
        std: standard deviations of fx, fy, u0, v0, k1, k2, p1, p2 (from σ² (JᵀJ)⁻¹ with
            σ² = SSR / (2N − p)), plus "rvecs" and "tvecs" (F, 3).
        n_iter: Levenberg–Marquardt steps.
        converged: whether the solver met its tolerance.
        init: the closed-form camera (zero distortion) the refinement started from.
        residuals: (F, N, 2) pixel residuals (padding zeroed), for plots.
        covariance: (p, p) covariance of all parameters (intrinsics first, then poses).
    """

    camera: Camera
    rvecs: np.ndarray
    tvecs: np.ndarray
    rms: float
    per_image_rms: np.ndarray
    std: dict
    n_iter: int
    converged: bool
    init: Camera
    residuals: np.ndarray
    covariance: np.ndarray

    @property
    def rotations(self) -> np.ndarray:
        """(F, 3, 3) board rotations."""
        with jax.enable_x64(True):
            return np.asarray(jax.vmap(rodrigues)(jnp.asarray(self.rvecs)))

    @property
    def board_planes(self) -> np.ndarray:
        """(F, 3) board planes a x + b y + c z + 1 = 0 in the camera frame."""
        return board_planes(self.rotations, self.tvecs)


def board_planes(R: ArrayLike, t: ArrayLike) -> np.ndarray:
    """Planes (F, 3) of boards at poses (R, t): normal n = R e_z, n·X = n·t → −n / (n·t)."""
    R = np.asarray(R, np.float64).reshape(-1, 3, 3)
    t = np.asarray(t, np.float64).reshape(-1, 3)
    n = R[:, :, 2]
    d = np.sum(n * t, axis=1)
    return -n / d[:, None]


def calibrate_camera(
    image_points: Sequence[ArrayLike],
    object_points: ArrayLike | Sequence[ArrayLike],
    image_size: tuple[int, int],
    *,
    rtol: float = 1e-12,
    atol: float = 1e-12,
    max_steps: int = 200,
) -> CameraCalibration:
    """Zhang's calibration: closed form, then joint maximum-likelihood LM refinement.

    Minimises Σ‖m_ij − m̂(K, k1, k2, p1, p2, R_i, t_i, M_j)‖² over all parameters (Zhang 2000,
    eq. (10); the paper's section 2.3), with OpenCV's distortion model (correction 1). The
    solver is `optimistix.LevenbergMarquardt` with `lineax.Normal(lineax.Cholesky())` on
    flattened, column-scaled parameters, in float64 whatever the global JAX setting.

    Args:
        image_points: per view (N_i, 2) pixels (e.g. from `detect_corners`, Nones removed).
        object_points: (N, 3) target points with z = 0 shared by all views, or one array per
            view.
        image_size: (width, height) in pixels.
        rtol, atol: LM tolerances on the scaled parameters.
        max_steps: LM step cap (non-convergence is reported in `converged`, not raised).

    Returns:
        A `CameraCalibration`.
    """
    image_size = (int(image_size[0]), int(image_size[1]))
    img, obj, mask = _pack(image_points, object_points)
    F = len(img)
    init, rvecs0, tvecs0 = zhang_init(image_points, object_points, image_size)
    with jax.enable_x64(True):
        p0 = jnp.concatenate(
            [
                jnp.stack([init.fx, init.fy, init.u0, init.v0]),
                jnp.zeros(4),
                jnp.asarray(rvecs0).ravel(),
                jnp.asarray(tvecs0).ravel(),
            ]
        )
        p, r, J, ok, steps = _refine_jit(
            p0, jnp.asarray(img), jnp.asarray(obj), jnp.asarray(mask), image_size,
            rtol, atol, max_steps,
        )  # fmt: skip
        p, r, J = np.asarray(p), np.asarray(r), np.asarray(J)
        cam, rv, tv = _unpack(jnp.asarray(p), F, image_size)
    n_pts = int(mask.sum())
    res = r.reshape(F, -1, 2)
    ssr = float(np.sum(r**2))
    per_image = np.sqrt(np.sum(res**2, axis=(1, 2)) / mask.sum(axis=1))
    n_par = p.size
    dof = 2 * n_pts - n_par
    if dof <= 0:
        raise CalibrationError(f"{n_pts} corners cannot determine {n_par} parameters")
    JtJ = J.T @ J
    try:
        cov = (ssr / dof) * np.linalg.inv(JtJ)
    except np.linalg.LinAlgError:
        cov = np.full_like(JtJ, np.nan)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    std = {k: float(sd[i]) for i, k in enumerate(_INTRINSIC_NAMES)}
    std["rvecs"] = sd[8 : 8 + 3 * F].reshape(F, 3)
    std["tvecs"] = sd[8 + 3 * F :].reshape(F, 3)
    return CameraCalibration(
        camera=cam,
        rvecs=np.asarray(rv),
        tvecs=np.asarray(tv),
        rms=float(np.sqrt(ssr / n_pts)),
        per_image_rms=per_image,
        std=std,
        n_iter=int(steps),
        converged=bool(ok),
        init=init,
        residuals=res,
        covariance=cov,
    )


# ----------------------------------------------------------------------------- laser planes


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


def _extract(image_rgb, stripe, mask, method):
    """Stripe centres (pos, valid) with `cslx.segment` when present, else the simple one."""
    if method == "auto":
        try:
            from . import segment  # noqa: F401

            method = "steger"
        except ImportError:
            method = "simple"
    if method == "simple":
        from ._calib_stripe import stripe_centres

        pos, valid, _ = stripe_centres(image_rgb, stripe, mask=mask)
        return np.asarray(pos, float), np.asarray(valid, bool)
    from .segment import extract

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
        method: "simple" (`cslx._calib_stripe`), a `cslx.segment.extract` method, or "auto".
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
            pos, valid = _extract(image, stripe, mask, method)
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


# ----------------------------------------------------------------------------- robot frame


@jax.jit
def _kabsch(P, Q):
    cp, cq = P.mean(axis=0), Q.mean(axis=0)
    H = (P - cp).T @ (Q - cq)
    U, _, Vt = jnp.linalg.svd(H)
    d = jnp.sign(jnp.linalg.det(Vt.T @ U.T))
    d = jnp.where(d == 0, 1.0, d)
    D = jnp.diag(jnp.stack([jnp.ones_like(d), jnp.ones_like(d), d]))
    R = Vt.T @ D @ U.T
    T = cq - R @ cp
    res = jnp.linalg.norm(P @ R.T + T - Q, axis=1)
    return R, T, res


def fit_rigid(P_camera: ArrayLike, P_robot: ArrayLike) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Rigid transform X_r = R X_c + T minimising Σ‖R P_c + T − P_r‖² (Kabsch; no scale).

    The paper's printed R_cr (Table 4) is not a rotation (correction 2); here the SVD solution
    is made proper (det R = +1) by flipping the sign of the last singular direction when the
    best orthogonal matrix is a reflection (Umeyama 1991).

    Args:
        P_camera: (N, 3) target points in the camera frame, mm.
        P_robot: (N, 3) the same points in the robot frame, mm.

    Returns:
        (R (3, 3), T (3,), residuals (N,) distances in mm), float64.

    Raises:
        CalibrationError: fewer than three points, or points (nearly) collinear.
    """
    P = np.asarray(P_camera, np.float64)
    Q = np.asarray(P_robot, np.float64)
    if P.ndim != 2 or P.shape[1] != 3 or P.shape != Q.shape:
        raise ValueError(f"point sets must both be (N, 3), got {P.shape} and {Q.shape}")
    if len(P) < 3:
        raise CalibrationError(f"a rigid fit needs at least 3 points, got {len(P)}")
    s = np.linalg.svd(P - P.mean(0), compute_uv=False)
    if s[1] < 1e-6 * max(s[0], 1e-300):
        raise CalibrationError("the robot calibration points are (nearly) collinear")
    with jax.enable_x64(True):
        R, T, res = _kabsch(jnp.asarray(P), jnp.asarray(Q))
        return np.asarray(R), np.asarray(T), np.asarray(res)


# ----------------------------------------------------------------------------- joint refinement


def _undistort_unrolled(xy_d, dist, n_iter: int = 40):
    """`cslx.camera.undistort` as a fixed number of the same fixed-point steps.

    Inside the LM solve the residuals are linearised and transposed (normal equations);
    through `optx.fixed_point`'s implicit adjoint that produced NaNs, so this path unrolls
    the iteration (contraction ≈ |k1| r² per step: 40 steps reach float64 precision for
    any lens `undistort` handles) and lets plain autodiff differentiate it.
    """
    return jax.lax.fori_loop(0, n_iter, lambda _, x: _undistort_step(x, (xy_d, dist)), xy_d)


def _stripe_residuals(p, planes, data):
    """Distances (mm) of lifted stripe points to their laser planes.

    A stripe pixel's ray meets its board (pose of its view) at X; X should lie on the laser
    plane n·X + 1 = 0 of its stripe, so the residual is (n·X + 1) / ‖n‖.
    """
    img, uv, view, plane_id, image_size = data
    cam, rvecs, tvecs = _unpack(p, img.shape[0], image_size)
    xy = jnp.stack([(uv[:, 0] - cam.u0) / cam.fx, (uv[:, 1] - cam.v0) / cam.fy], axis=-1)
    ray = jnp.concatenate([_undistort_unrolled(xy, cam.dist), jnp.ones_like(xy[:, :1])], -1)
    R = jax.vmap(rodrigues)(rvecs)[view]
    t = tvecs[view]
    nb = R[:, :, 2]
    X = ray * (jnp.sum(nb * t, axis=1) / jnp.sum(nb * ray, axis=1))[:, None]
    n = planes[plane_id]
    return (jnp.sum(n * X, axis=1) + 1) / jnp.linalg.norm(n, axis=1)


def _joint_residuals(q, args, image_size):
    img, obj, mask, uv, view, plane_id, w_stripe, w_orth = args
    p, planes = q[:-6], q[-6:].reshape(2, 3)
    r_c = _reprojection(p, (img, obj, mask, image_size))
    r_s = _stripe_residuals(p, planes, (img, uv, view, plane_id, image_size)) * w_stripe
    cos = planes[0] @ planes[1] / (jnp.linalg.norm(planes[0]) * jnp.linalg.norm(planes[1]))
    return jnp.concatenate([r_c, r_s, (w_orth * cos)[None]])


def _joint_impl(q0, args, image_size, rtol, atol, max_steps):
    def fn(q, a):
        return _joint_residuals(q, a, image_size)

    J0 = jax.jacfwd(fn)(q0, args)
    s = 1.0 / jnp.maximum(jnp.linalg.norm(J0, axis=0), 1e-12)
    solver = optx.LevenbergMarquardt(rtol=rtol, atol=atol, linear_solver=lx.Normal(lx.Cholesky()))
    sol = optx.least_squares(
        _scaled(fn), solver, q0 / s, args=(args, s), max_steps=max_steps, throw=False
    )
    q = sol.value * s
    return q, fn(q, args), jax.jacfwd(fn)(q, args), sol.stats["num_steps"]


_joint_jit = jax.jit(_joint_impl, static_argnums=(2, 5))


@dataclasses.dataclass(frozen=True)
class JointCalibration:
    """Result of `refine_sensor`: camera, poses and both planes refined together.

    Attributes:
        camera, rvecs, tvecs: as in `CameraCalibration`.
        planes: (2, 3) laser planes; plane_std (2, 3) their standard deviations.
        rms: corner RMS reprojection error, px; plane_rms_mm (2,): stripe-point distances.
        angle_deg: angle between the planes.
        covariance: of all parameters (intrinsics, poses, then the six plane coefficients).
        n_iter: LM steps.
    """

    camera: Camera
    rvecs: np.ndarray
    tvecs: np.ndarray
    planes: np.ndarray
    plane_std: np.ndarray
    rms: float
    plane_rms_mm: np.ndarray
    angle_deg: float
    covariance: np.ndarray
    n_iter: int


def refine_sensor(
    calib: CameraCalibration,
    planes: PlaneCalibration,
    image_points: Sequence[ArrayLike],
    object_points: ArrayLike | Sequence[ArrayLike],
    *,
    orthogonal: bool = False,
    max_steps: int = 200,
) -> JointCalibration:
    """Refine the camera, every pose and both laser planes together (beyond the paper).

    The paper fits the planes after the camera, so the poses' errors pass into the planes
    unchecked. Here one maximum-likelihood problem holds the corners' pixel residuals and the
    stripe points' plane distances (each lifted through its own board pose), the latter
    weighted by σ_px / σ_mm,k from the separate fits so that both kinds are whitened alike.
    Only the stripe points kept as inliers by `fit_plane` enter. `orthogonal=True` adds a
    stiff penalty 10⁴ σ_px · cos∠(n0, n1): the cross projector's sheets are made
    perpendicular by construction (the paper reports 89.9981°).

    Returns:
        A `JointCalibration`.
    """
    img, obj, mask = _pack(image_points, object_points)
    F = len(img)
    if F != len(calib.rvecs):
        raise ValueError(f"{F} views of corners for {len(calib.rvecs)} calibrated poses")
    uv = np.concatenate([planes.pixels[k][planes.fits[k].inliers] for k in range(2)])
    view = np.concatenate([planes.views[k][planes.fits[k].inliers] for k in range(2)])
    pid = np.concatenate([np.full(int(planes.fits[k].inliers.sum()), k) for k in range(2)])
    sigma_px = calib.rms / np.sqrt(2)
    w_stripe = np.where(pid == 0, sigma_px / planes.fits[0].rms, sigma_px / planes.fits[1].rms)
    w_orth = 1e4 * sigma_px if orthogonal else 0.0
    cam = calib.camera
    with jax.enable_x64(True):
        q0 = jnp.concatenate(
            [
                jnp.stack([cam.fx, cam.fy, cam.u0, cam.v0]),
                cam.dist,
                jnp.asarray(calib.rvecs).ravel(),
                jnp.asarray(calib.tvecs).ravel(),
                jnp.asarray(planes.planes).ravel(),
            ]
        ).astype(jnp.float64)
        args = (
            jnp.asarray(img), jnp.asarray(obj), jnp.asarray(mask), jnp.asarray(uv),
            jnp.asarray(view), jnp.asarray(pid), jnp.asarray(w_stripe), jnp.asarray(w_orth),
        )  # fmt: skip
        q, r, J, steps = _joint_jit(q0, args, cam.image_size, 1e-12, 1e-12, max_steps)
        q, r, J = np.asarray(q), np.asarray(r), np.asarray(J)
        cam_o, rv, tv = _unpack(jnp.asarray(q[:-6]), F, cam.image_size)
    n_c = int(mask.sum())
    r_c = r[: img.size]
    r_s = r[img.size : img.size + len(uv)] / w_stripe
    dof = max(len(r) - 1 - q.size, 1)  # the orthogonality row is a constraint, not data
    s2 = float(np.sum(r[:-1] ** 2)) / dof
    try:
        cov = s2 * np.linalg.inv(J.T @ J)
    except np.linalg.LinAlgError:
        cov = np.full((q.size, q.size), np.nan)
    sd = np.sqrt(np.clip(np.diag(cov), 0, None))
    pl = q[-6:].reshape(2, 3)
    return JointCalibration(
        camera=cam_o,
        rvecs=np.asarray(rv),
        tvecs=np.asarray(tv),
        planes=pl,
        plane_std=sd[-6:].reshape(2, 3),
        rms=float(np.sqrt(np.sum(r_c**2) / n_c)),
        plane_rms_mm=np.array([np.sqrt(np.mean(r_s[pid == k] ** 2)) for k in range(2)]),
        angle_deg=plane_angle_deg(pl[0], pl[1]),
        covariance=cov,
        n_iter=int(steps),
    )
