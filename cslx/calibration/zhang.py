"""Closed-form pieces of Zhang's calibration (Zhang 2000, paper eqs. (5)–(7)), in JAX.

Rotation vectors, normalised DLT homographies, the
linear system V b = 0 for the image of the absolute conic, and the poses from H = K [r1 r2 t].
Views are padded to a common number of points; `mask` (1 for a real point, 0 for padding)
removes the padding from every sum.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, Float

from ..sensor.camera import Camera
from ..sensor.rig import CalibrationError


def rodrigues(rvec: Float[Array, 3]) -> Float[Array, "3 3"]:
    """Rotation vector → rotation matrix (Rodrigues' formula, as `cv2.Rodrigues`).

    R = I + (sin θ / θ) [r]ₓ + ((1 − cos θ) / θ²) [r]ₓ², with Taylor series below θ² = 1e-8 so
    that the value and the gradient stay finite at θ = 0.
    """
    th2 = rvec @ rvec
    small = th2 < 1e-8
    safe2 = jnp.where(small, jnp.ones_like(th2), th2)
    th = jnp.sqrt(safe2)
    a = jnp.where(small, 1 - th2 / 6, jnp.sin(th) / th)
    b = jnp.where(small, 0.5 - th2 / 24, (1 - jnp.cos(th)) / safe2)
    x, y, z = rvec[0], rvec[1], rvec[2]
    zero = jnp.zeros_like(x)
    k = jnp.stack([jnp.stack([zero, -z, y]), jnp.stack([z, zero, -x]), jnp.stack([-y, x, zero])])
    return jnp.eye(3, dtype=rvec.dtype) + a * k + b * (k @ k)


def rotation_to_rvec(R: Float[Array, "3 3"]) -> Float[Array, 3]:
    """Rotation matrix → rotation vector via a quaternion (Shepperd's method; stable near π)."""
    tr = jnp.trace(R)
    d = jnp.diagonal(R)
    t = jnp.stack([1 + tr, 1 + 2 * d[0] - tr, 1 + 2 * d[1] - tr, 1 + 2 * d[2] - tr])
    cands = jnp.stack(
        [
            jnp.stack([t[0], R[2, 1] - R[1, 2], R[0, 2] - R[2, 0], R[1, 0] - R[0, 1]]),
            jnp.stack([R[2, 1] - R[1, 2], t[1], R[0, 1] + R[1, 0], R[0, 2] + R[2, 0]]),
            jnp.stack([R[0, 2] - R[2, 0], R[0, 1] + R[1, 0], t[2], R[1, 2] + R[2, 1]]),
            jnp.stack([R[1, 0] - R[0, 1], R[0, 2] + R[2, 0], R[1, 2] + R[2, 1], t[3]]),
        ]
    )
    k = jnp.argmax(t)
    q = cands[k] * 0.5 / jnp.sqrt(jnp.maximum(t[k], 1e-30))
    q = q * jnp.where(q[0] < 0, -1.0, 1.0)  # w ≥ 0: the angle lies in [0, π]
    v = q[1:]
    s = jnp.linalg.norm(v)
    safe_s = jnp.where(s < 1e-15, 1.0, s)
    angle = 2 * jnp.arctan2(s, q[0])
    return jnp.where(s < 1e-15, 2 * v, v * (angle / safe_s))


def _normaliser(p: Float[Array, "n 2"], mask: Float[Array, " n"]) -> Float[Array, "3 3"]:
    """Hartley normalisation: centroid to the origin, mean distance √2."""
    m = jnp.sum(mask)
    c = jnp.sum(p * mask[:, None], axis=0) / m
    dist = jnp.sqrt(jnp.sum((p - c) ** 2, axis=-1))
    s = jnp.sqrt(2.0) / (jnp.sum(dist * mask) / m)
    o = jnp.zeros_like(s)
    return jnp.array([[s, o, -s * c[0]], [o, s, -s * c[1]], [o, o, o + 1]])


def homography(
    obj: Float[Array, "n 2"], img: Float[Array, "n 2"], mask: Float[Array, " n"]
) -> Float[Array, "3 3"]:
    """Board plane (x_t, y_t) → pixels homography by the normalised DLT (eq. (6)).

    The paper refines H by eq. (7) before use; here the joint maximum-likelihood refinement
    that follows makes that step unnecessary, so H is the linear estimate, scaled to ‖H‖ = 1.
    """
    Ta, Tb = _normaliser(obj, mask), _normaliser(img, mask)
    a = obj @ Ta[:2, :2].T + Ta[:2, 2]
    b = img @ Tb[:2, :2].T + Tb[:2, 2]
    one = jnp.ones_like(a[:, :1])
    ah = jnp.concatenate([a, one], axis=1)
    rows_u = jnp.concatenate([ah, jnp.zeros_like(ah), -b[:, :1] * ah], axis=1)
    rows_v = jnp.concatenate([jnp.zeros_like(ah), ah, -b[:, 1:] * ah], axis=1)
    A = jnp.concatenate([rows_u, rows_v], axis=0) * jnp.concatenate([mask, mask])[:, None]
    _, _, vt = jnp.linalg.svd(A.T @ A)
    Hn = vt[-1].reshape(3, 3)
    H = jnp.linalg.solve(Tb, Hn @ Ta)
    return H / jnp.linalg.norm(H)


def _v(H: Float[Array, "3 3"], i: int, j: int) -> Float[Array, 6]:
    hi, hj = H[:, i], H[:, j]
    return jnp.stack(
        [
            hi[0] * hj[0],
            hi[0] * hj[1] + hi[1] * hj[0],
            hi[1] * hj[1],
            hi[2] * hj[0] + hi[0] * hj[2],
            hi[2] * hj[1] + hi[1] * hj[2],
            hi[2] * hj[2],
        ]
    )


def intrinsics_from_homographies(
    Hs: Float[Array, "f 3 3"], image_size: tuple[int, int]
) -> Float[Array, "3 3"]:
    """Zhang's closed form: solve V b = 0 by SVD and read K from B = K⁻ᵀ K⁻¹ (Appendix B).

    The homographies are first mapped to coordinates of order one (pixels scaled by the image
    size) so that V is well conditioned, and a zero-skew row (B12 = 0) is appended, which makes
    two views enough. Skew is dropped from the result (the camera model has none).
    """
    w, h = image_size
    N = jnp.array([[2.0 / w, 0, -1], [0, 2.0 / h, -1], [0, 0, 1]], dtype=Hs.dtype)
    Hn = jnp.einsum("ij,fjk->fik", N, Hs)
    Hn = Hn / jnp.linalg.norm(Hn, axis=(1, 2), keepdims=True)
    v12 = jax.vmap(lambda H: _v(H, 0, 1))(Hn)
    vdd = jax.vmap(lambda H: _v(H, 0, 0) - _v(H, 1, 1))(Hn)
    skew = jnp.array([[0, 1.0, 0, 0, 0, 0]], dtype=Hs.dtype)
    V = jnp.concatenate([v12, vdd, skew], axis=0)
    _, _, vt = jnp.linalg.svd(V)
    b = vt[-1]
    b = jnp.where(b[0] < 0, -b, b)
    B11, B12, B22, B13, B23, B33 = b
    den = B11 * B22 - B12**2
    v0 = (B12 * B13 - B11 * B23) / den
    lam = B33 - (B13**2 + v0 * (B12 * B13 - B11 * B23)) / B11
    alpha = jnp.sqrt(lam / B11)
    beta = jnp.sqrt(lam * B11 / den)
    gamma = -B12 * alpha**2 * beta / lam
    u0 = gamma * v0 / beta - B13 * alpha**2 / lam
    o = jnp.zeros_like(alpha)
    Kn = jnp.array([[alpha, o, u0], [o, beta, v0], [o, o, o + 1]])
    return jnp.linalg.solve(N, Kn)


def pose_from_homography(
    K: Float[Array, "3 3"], H: Float[Array, "3 3"]
) -> tuple[Float[Array, 3], Float[Array, 3]]:
    """H = λ K [r1 r2 t] → (rotation vector, t), with [r1 r2 r1×r2] made a proper rotation.

    The sign of λ puts the board in front of the camera (t_z > 0); the nearest rotation in the
    Frobenius norm is U Vᵀ of the SVD (Zhang 2000, Appendix C).
    """
    M = jnp.linalg.solve(K, H)
    lam = 1.0 / jnp.linalg.norm(M[:, 0])
    lam = jnp.where(M[2, 2] * lam < 0, -lam, lam)
    r1, r2, t = lam * M[:, 0], lam * M[:, 1], lam * M[:, 2]
    Q = jnp.stack([r1, r2, jnp.cross(r1, r2)], axis=1)
    U, _, Vt = jnp.linalg.svd(Q)
    d = jnp.sign(jnp.linalg.det(U @ Vt))
    R = U @ jnp.diag(jnp.array([1.0, 1.0, 1.0], dtype=Q.dtype).at[2].set(d)) @ Vt
    return rotation_to_rvec(R), t


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
