"""Rendered calibration boards (chessboards with and without the laser cross on them)."""

from __future__ import annotations

import math

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from ..sensor import Sensor, default_sensor
from ..sensor.camera import pixel_to_ray, project
from .render import _as_f32, _nz_arrays
from .shade import (
    Nuisance,
    checkerboard_radiance,
    expose,
    pixel_grid,
    quantise,
)


def _rodrigues(v):
    th = np.linalg.norm(v)
    if th < 1e-12:
        return np.eye(3)
    k = v / th
    K = np.array([[0, -k[2], k[1]], [k[2], 0, -k[0]], [-k[1], k[0], 0]])
    return np.eye(3) + math.sin(th) * K + (1 - math.cos(th)) * K @ K


def _board_poses(sensor, n, rng, pattern, square, max_tries=20000):
    """Random board→camera poses with the whole board in view and both stripes across it."""
    import cv2

    cols, rows = pattern
    cam = sensor.camera
    W, H = cam.image_size
    K = np.asarray(cam.K, float)
    dist = np.asarray(cam.dist, float)
    planes = np.asarray(sensor.planes, float)
    # Inner corners plus half a square must be in view for the detector.
    outline = np.array(
        [[-0.5, -0.5, 0], [cols - 0.5, -0.5, 0], [-0.5, rows - 0.5, 0], [cols - 0.5, rows - 0.5, 0]]
    )
    outline = outline * square
    # The board's printed area (the squares and half a square of white margin).
    gx, gy = np.meshgrid(np.linspace(-1.5, cols + 0.5, 25), np.linspace(-1.5, rows + 0.5, 19))
    inner = np.stack([gx.ravel(), gy.ravel(), np.zeros(gx.size)], 1) * square
    centre = np.array([(cols - 1) / 2, (rows - 1) / 2, 0.0]) * square
    Rs, ts = [], []
    for _ in range(max_tries):
        R = _rodrigues(
            np.array([np.deg2rad(rng.uniform(-25, 25)), np.deg2rad(rng.uniform(-25, 25)), 0.0])
        ) @ _rodrigues(np.array([0.0, 0.0, np.deg2rad(rng.uniform(-10, 10))]))
        z = rng.uniform(380, 540)
        # Centre the board a little right of and below the image centre, where the cross
        # projector's stripes fall at these distances.
        u_c, v_c = rng.uniform(340, 430), rng.uniform(240, 300)
        target = np.array([(u_c - K[0, 2]) * z / K[0, 0], (v_c - K[1, 2]) * z / K[1, 1], z])
        t = target - R @ centre
        uv = cv2.projectPoints(outline, cv2.Rodrigues(R)[0], t, K, dist)[0][:, 0]
        if not (np.all(uv > 8) and np.all(uv[:, 0] < W - 9) and np.all(uv[:, 1] < H - 9)):
            continue
        # Each sheet must split the printed board, with ≥ 5 % of it on either side.
        X = inner @ R.T + t
        side = (X @ planes.T + 1) > 0
        frac = side.mean(axis=0)
        if np.any(np.minimum(frac, 1 - frac) < 0.05):
            continue
        Rs.append(R)
        ts.append(t)
        if len(Rs) == n:
            return np.stack(Rs), np.stack(ts)
    raise RuntimeError(
        f"found only {len(Rs)} of {n} board poses with the board in view and both stripes "
        "across it; the sensor's projector may not reach the board at 380–540 mm"
    )


def _projector(sensor):
    from .scene import projector_origin

    return projector_origin(sensor)


def _axis(sensor):
    from .scene import projector_axis

    return projector_axis(sensor)


@eqx.filter_jit
def _grid_rays(sensor, ss):
    return pixel_to_ray(
        pixel_grid(sensor.camera.image_size, ss, sensor.planes.dtype), sensor.camera
    )


@eqx.filter_jit
def _checker_kernel(sensor, ray, R, t, nz, key, laser_on, pattern, square, ss):
    bg, laser = checkerboard_radiance(sensor, ray, R, t, laser_on, nz, pattern, square, ss)
    return quantise(expose(bg, laser, nz, key))


def render_calibration(
    sensor: Sensor | None = None,
    n_poses: int = 15,
    seed: int = 0,
    pattern: tuple[int, int] = (10, 7),
    square_mm: float = 25.0,
    *,
    nuisance: Nuisance | None = None,
    supersample: int = 6,
    progress: bool = False,
) -> dict[str, np.ndarray]:
    """Checkerboard images in random poses, each without and with the laser (paper, 2.3).

    The board (cols × rows inner corners at (i·square, j·square, 0), i fastest) is rendered
    with `supersample`² rays per pixel through the distorted lens, 380–540 mm away, tilted
    up to 25°, and posed so that both laser stripes cross its printed area.

    Returns:
        `plain`, `laser` (F, H, W, 3) uint8; `R` (F, 3, 3), `t` (F, 3) the true board→camera
        poses (X_c = R X_b + t, OpenCV convention); `object_points` (N, 3);
        `image_points` (F, N, 2) the true distorted projections of the corners.
    """
    sensor = sensor or default_sensor()
    rng = np.random.default_rng([seed, 555])
    nz = nuisance or Nuisance(ambient=170.0, laser_power=220.0, speckle=0.3, texture=0.0)
    cols, rows = pattern
    obj = np.zeros((cols * rows, 3))
    obj[:, :2] = np.mgrid[0:cols, 0:rows].T.reshape(-1, 2) * square_mm
    Rs, ts = _board_poses(sensor, n_poses, rng, pattern, square_mm)
    s32 = _as_f32(sensor)
    nz32 = _nz_arrays(nz)
    rays = _grid_rays(s32, int(supersample))
    plain, laser, img_pts = [], [], []
    it = range(n_poses)
    if progress:
        from tqdm import tqdm

        it = tqdm(it, desc="render calibration")
    for i in it:
        R32, t32 = jnp.asarray(Rs[i], jnp.float32), jnp.asarray(ts[i], jnp.float32)
        for on, out in ((False, plain), (True, laser)):
            key = jax.random.key(int(seed) * 7919 + 2 * i + int(on))
            out.append(
                np.array(
                    _checker_kernel(
                        s32,
                        rays,
                        R32,
                        t32,
                        nz32,
                        key,
                        on,
                        tuple(pattern),
                        float(square_mm),
                        supersample,
                    )
                )
            )
        img_pts.append(np.asarray(project(jnp.asarray(obj @ Rs[i].T + ts[i]), sensor.camera)))
    return dict(
        plain=np.stack(plain),
        laser=np.stack(laser),
        R=Rs,
        t=ts,
        object_points=obj,
        image_points=np.stack(img_pts),
    )
