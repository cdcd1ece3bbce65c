"""Rendered calibration boards: chessboards without and with the laser (a cross or one line)."""

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


def _board_poses(
    sensor,
    n,
    rng,
    pattern,
    square,
    max_tries=20000,
    lines=(0, 1),
    distance_mm=(380.0, 540.0),
    centre_px=((340.0, 430.0), (240.0, 300.0)),
):
    """Random board→camera poses with the whole board in view and the drawn stripes across it."""
    import cv2

    cols, rows = pattern
    cam = sensor.camera
    W, H = cam.image_size
    K = np.asarray(cam.K, float)
    dist = np.asarray(cam.dist, float)
    planes = np.asarray(sensor.planes, float)[list(lines)]
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
        z = rng.uniform(*distance_mm)
        # By default the board is centred a little right of and below the image centre,
        # where the default cross projector's stripes fall at 380–540 mm.
        u_c, v_c = rng.uniform(*centre_px[0]), rng.uniform(*centre_px[1])
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
        f"found only {len(Rs)} of {n} board poses with the board in view and the stripes "
        f"across it; the sensor's projector may not reach the board at {distance_mm} mm"
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
def _checker_kernel(sensor, ray, R, t, nz, key, laser_on, pattern, square, ss, lines):
    bg, laser = checkerboard_radiance(sensor, ray, R, t, laser_on, nz, pattern, square, ss, lines)
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
    lines: tuple[str, ...] = ("h", "v"),
    distance_mm: tuple[float, float] = (380.0, 540.0),
    centre_px: tuple[tuple[float, float], tuple[float, float]] = ((340, 430), (240, 300)),
) -> dict[str, np.ndarray]:
    """Checkerboard images in random poses, each without and with the laser (paper, 2.3).

    The board (cols × rows inner corners at (i·square, j·square, 0), i fastest) is rendered
    with `supersample`² rays per pixel through the distorted lens, `distance_mm` away
    (default 380–540 mm), its centre imaged within `centre_px` ((u range), (v range)), tilted
    up to 25°, and posed so that the drawn laser stripes cross its printed area.

    `lines` chooses the laser: ("h", "v") the sensor's cross, ("h",) or ("v",) a single line
    laser drawing only that stripe's sheet (the sensor's plane of that stripe).

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
    rows_on = tuple(sensor.plane_index(s) for s in lines)
    if not rows_on:
        raise ValueError("lines must name at least one stripe ('h', 'v')")
    Rs, ts = _board_poses(
        sensor, n_poses, rng, pattern, square_mm, lines=rows_on, distance_mm=distance_mm,
        centre_px=centre_px,
    )  # fmt: skip
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
                        rows_on,
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
