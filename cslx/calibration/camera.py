"""Camera calibration: Zhang's closed form refined by Levenberg–Marquardt (eqs. (5)–(7)).

The closed-form start (`cslx.calibration.zhang`) is refined jointly over the intrinsics
(fx, fy, u0, v0, k1, k2, p1, p2) and every board pose (rotation vectors) by optimistix's
Levenberg–Marquardt with Cholesky normal equations in float64. The distortion is OpenCV's
Brown–Conrady model (the project's correction of the garbled eq. (4)), so the result is the
minimiser of the same objective as `cv2.calibrateCamera(flags=CALIB_FIX_K3)`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import Array, ArrayLike, Float

from ..sensor.camera import Camera, distort
from ..sensor.rig import CalibrationError
from .zhang import (
    _pack,
    rodrigues,
    zhang_init,
)

_INTRINSIC_NAMES = ("fx", "fy", "u0", "v0", "k1", "k2", "p1", "p2")


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
