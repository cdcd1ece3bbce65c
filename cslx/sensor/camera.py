"""Pinhole camera with Brown–Conrady lens distortion, exactly as OpenCV defines it.

The paper's eq. (4) is garbled (docs/corrections.md, 1). cslx uses OpenCV's model
with normalised coordinates (x, y) = (X/Z, Y/Z) and r² = x² + y²:

    x_d = x (1 + k1 r² + k2 r⁴) + 2 p1 x y + p2 (r² + 2 x²)
    y_d = y (1 + k1 r² + k2 r⁴) + p1 (r² + 2 y²) + 2 p2 x y
    u = fx x_d + u0,   v = fy y_d + v0                       (eqs. (2)–(3))

Undistortion has no closed form; it is solved as the fixed point
x = (x_d − δ_t(x)) / (1 + k1 r² + k2 r⁴) with `optimistix.fixed_point`, which also
gives exact (implicit-function) gradients.

Pixel coordinates are OpenCV's: origin at the centre of the top-left pixel, u to the
right, v down. Every function is pure, works on any leading batch shape and is
jit-, vmap- and grad-friendly; the dtype follows the inputs.
"""

from __future__ import annotations

from typing import TYPE_CHECKING

import jax
import jax.numpy as jnp
import numpy as np

from ..pytree import pytree_dataclass, static

if TYPE_CHECKING:  # annotations only (strings at run time): no jaxtyping import
    from jaxtyping import Array, ArrayLike, Float

__all__ = [
    "Camera",
    "distort",
    "undistort",
    "project",
    "pixel_to_normalized",
    "pixel_to_ray",
    "normalized_to_pixel",
    "undistort_step",
]


@pytree_dataclass(eq=False)
class Camera:
    """Intrinsics of a pinhole camera with (k1, k2, p1, p2) distortion.

    An immutable pytree (a frozen dataclass registered with JAX; not an `equinox.Module`,
    whose import costs ≈ 0.14 s of the tracker's start-up, issue 13).

    Attributes:
        fx, fy: focal lengths in pixels.
        u0, v0: principal point in pixels (OpenCV convention).
        dist: (4,) distortion coefficients (k1, k2, p1, p2), OpenCV order.
        image_size: (width, height) in pixels; static, it shapes compiled programs.
    """

    fx: Float[Array, ""]
    fy: Float[Array, ""]
    u0: Float[Array, ""]
    v0: Float[Array, ""]
    dist: Float[Array, 4]
    image_size: tuple[int, int] = static((640, 480))

    @classmethod
    def from_matrix(
        cls, K: ArrayLike, dist: ArrayLike, image_size: tuple[int, int] = (640, 480)
    ) -> Camera:
        """Build from a 3×3 intrinsic matrix K and (k1, k2, p1, p2).

        Concrete values are sliced in NumPy and placed with `jax.device_put`: eager `jnp`
        indexing and casts compile a small XLA program each, read from the compile cache at
        every start of the tracker (issue 13); traced values take the `jnp` path.
        """
        if isinstance(K, jax.core.Tracer) or isinstance(dist, jax.core.Tracer):
            K = jnp.asarray(K)
            dist = jnp.asarray(dist, dtype=K.dtype)
            take = lambda x: x  # noqa: E731
        else:
            K = np.asarray(K)
            K = K.astype(jax.dtypes.canonicalize_dtype(K.dtype))
            dist = np.asarray(dist, dtype=K.dtype)
            take = jax.device_put
        if dist.shape != (4,):
            raise ValueError(f"dist must hold (k1, k2, p1, p2), got shape {dist.shape}")
        fx, fy, u0, v0 = (take(K[i, j]) for i, j in ((0, 0), (1, 1), (0, 2), (1, 2)))
        return cls(fx, fy, u0, v0, take(dist), tuple(int(s) for s in image_size))

    @property
    def K(self) -> Float[Array, "3 3"]:
        """The 3×3 intrinsic matrix of eq. (3)."""
        z = jnp.zeros_like(self.fx)
        o = jnp.ones_like(self.fx)
        return jnp.stack(
            [
                jnp.stack([self.fx, z, self.u0]),
                jnp.stack([z, self.fy, self.v0]),
                jnp.stack([z, z, o]),
            ]
        )

    @property
    def width(self) -> int:
        return self.image_size[0]

    @property
    def height(self) -> int:
        return self.image_size[1]


def distort(xy: Float[Array, "*b 2"], dist: Float[Array, 4]) -> Float[Array, "*b 2"]:
    """Apply Brown–Conrady distortion to normalised coordinates (correction 1 of eq. (4))."""
    k1, k2, p1, p2 = dist[0], dist[1], dist[2], dist[3]
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    xd = x * radial + 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    yd = y * radial + p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return jnp.stack([xd, yd], axis=-1)


def undistort_step(xy, args):
    """One step x ← x_d − δ(x) of the undistortion fixed point; `args` = (x_d, dist)."""
    xy_d, dist = args
    k1, k2, p1, p2 = dist[0], dist[1], dist[2], dist[3]
    x, y = xy[..., 0], xy[..., 1]
    r2 = x * x + y * y
    radial = 1 + k1 * r2 + k2 * r2 * r2
    dx = 2 * p1 * x * y + p2 * (r2 + 2 * x * x)
    dy = p1 * (r2 + 2 * y * y) + 2 * p2 * x * y
    return jnp.stack([(xy_d[..., 0] - dx) / radial, (xy_d[..., 1] - dy) / radial], axis=-1)


def _default_tol(dtype) -> float:
    return 1e-12 if jnp.finfo(dtype).bits >= 64 else 1e-6


def undistort(
    xy_d: Float[Array, "*b 2"],
    dist: Float[Array, 4],
    *,
    tol: float | None = None,
    max_steps: int = 100,
) -> Float[Array, "*b 2"]:
    """Invert `distort`: distorted normalised coordinates → ideal normalised coordinates.

    Solves x = (x_d − δ_t(x)) / (1 + k1 r² + k2 r⁴) as a fixed point with
    `optimistix.FixedPointIteration` (the same iteration as `cv2.undistortPoints`, but run to
    convergence rather than a fixed five steps). All points form one fixed-point problem, so
    the cost is one small loop whatever the batch shape; gradients come from the implicit
    function theorem.

    Args:
        xy_d: distorted normalised coordinates, any leading shape.
        dist: (k1, k2, p1, p2).
        tol: relative and absolute tolerance; defaults to 1e-12 in float64, 1e-6 in float32.
        max_steps: iteration cap. A failure to converge is not raised (it would break `vmap`);
            the last iterate is returned.
    """
    xy_d = jnp.asarray(xy_d)
    out_dtype = xy_d.dtype
    # optimistix keeps its convergence state in the default float dtype; with x64 enabled a
    # float32 problem would mix dtypes inside its loop, so solve in the default dtype.
    xy_d = xy_d.astype(jnp.result_type(float))
    dist = jnp.asarray(dist, dtype=xy_d.dtype)
    tol = _default_tol(out_dtype) if tol is None else tol
    import optimistix as optx  # lazy: importing cslx.runtime does not need it

    solver = optx.FixedPointIteration(rtol=tol, atol=tol)
    sol = optx.fixed_point(
        undistort_step,
        solver,
        xy_d,
        args=(xy_d, dist),
        max_steps=max_steps,
        throw=False,
    )
    return sol.value.astype(out_dtype)


def normalized_to_pixel(xy_d: Float[Array, "*b 2"], camera: Camera) -> Float[Array, "*b 2"]:
    """Distorted normalised coordinates → pixels (eq. (2)–(3), no skew)."""
    return jnp.stack(
        [camera.fx * xy_d[..., 0] + camera.u0, camera.fy * xy_d[..., 1] + camera.v0], axis=-1
    )


def project(points: Float[Array, "*b 3"], camera: Camera) -> Float[Array, "*b 2"]:
    """Project camera-frame 3-D points (mm) to distorted pixel coordinates.

    Equivalent to `cv2.projectPoints` with rvec = tvec = 0. Points must lie in front of the
    camera (Z > 0); behind it the result is meaningless, as in OpenCV.
    """
    points = jnp.asarray(points)
    z = points[..., 2]
    safe_z = jnp.where(z == 0, jnp.ones_like(z), z)
    xy = points[..., :2] / safe_z[..., None]
    return normalized_to_pixel(distort(xy, camera.dist.astype(xy.dtype)), camera)


def pixel_to_normalized(
    uv: Float[Array, "*b 2"], camera: Camera, *, tol: float | None = None
) -> Float[Array, "*b 2"]:
    """Pixels → undistorted normalised coordinates (like `cv2.undistortPoints` without R, P)."""
    uv = jnp.asarray(uv)
    xy_d = jnp.stack(
        [(uv[..., 0] - camera.u0) / camera.fx, (uv[..., 1] - camera.v0) / camera.fy], axis=-1
    )
    return undistort(xy_d, camera.dist.astype(xy_d.dtype), tol=tol)


def pixel_to_ray(
    uv: Float[Array, "*b 2"], camera: Camera, *, normalize: bool = True
) -> Float[Array, "*b 3"]:
    """Pixels → viewing rays in the camera frame (first step of correction 3 of eq. (27)).

    Args:
        uv: pixel coordinates, OpenCV convention.
        camera: the intrinsics.
        normalize: unit rays if True, else rays with z = 1.
    """
    xy = pixel_to_normalized(uv, camera)
    ray = jnp.concatenate([xy, jnp.ones_like(xy[..., :1])], axis=-1)
    if normalize:
        ray = ray / jnp.linalg.norm(ray, axis=-1, keepdims=True)
    return ray


# A convenience for callers that want a compiled projector without building one themselves.
project_jit = jax.jit(project)
