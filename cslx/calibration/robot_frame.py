"""Camera-to-robot transform: a rigid fit (Kabsch, no scale, det R = +1) of known points."""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import ArrayLike

from ..sensor.rig import CalibrationError


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
