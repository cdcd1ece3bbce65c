"""Joint refinement of camera, board poses and laser planes from corners and stripe points.

Beyond the paper: one Levenberg–Marquardt problem over the intrinsics, the poses and
both planes, with an optional orthogonality constraint between the planes.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Sequence

import jax
import jax.numpy as jnp
import lineax as lx
import numpy as np
import optimistix as optx
from jaxtyping import ArrayLike

from ..sensor.camera import Camera, undistort_step
from ..sensor.rig import CalibrationError, plane_angle_deg
from .camera import CameraCalibration, _reprojection, _scaled, _unpack
from .planes import PlaneCalibration
from .zhang import (
    _pack,
    rodrigues,
)


def _undistort_unrolled(xy_d, dist, n_iter: int = 40):
    """`cslx.sensor.camera.undistort` as a fixed number of the same fixed-point steps.

    Inside the LM solve the residuals are linearised and transposed (normal equations);
    through `optx.fixed_point`'s implicit adjoint that produced NaNs, so this path unrolls
    the iteration (contraction ≈ |k1| r² per step: 40 steps reach float64 precision for
    any lens `undistort` handles) and lets plain autodiff differentiate it.
    """
    return jax.lax.fori_loop(0, n_iter, lambda _, x: undistort_step(x, (xy_d, dist)), xy_d)


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
    if len(planes.planes) != 2:
        raise CalibrationError(
            f"the joint refinement needs both planes of the cross; this calibration has "
            f"{len(planes.planes)} ({', '.join(planes.stripes)})"
        )
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
