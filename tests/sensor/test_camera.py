"""Camera model against OpenCV: projection, undistortion, round trips, jit/vmap/grad."""

import cv2
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.sensor import TABLE4_DIST, TABLE4_K
from cslx.sensor.camera import Camera, distort, pixel_to_ray, project, undistort

DISTORTIONS = {
    "paper_table4": TABLE4_DIST,  # k1 = -0.29: strong barrel distortion
    "opencv_left": (-0.2899, 0.1002, 0.00121, -0.000148),
    "pincushion": (0.15, -0.05, 0.002, -0.003),
    "none": (0.0, 0.0, 0.0, 0.0),
}


def _camera(dist):
    return Camera.from_matrix(np.array(TABLE4_K), np.array(dist), (640, 480))


def _points(n=400, seed=0):
    rng = np.random.default_rng(seed)
    z = rng.uniform(150, 400, n)
    # Cover the whole 640x480 image and a little beyond.
    x = rng.uniform(-0.42, 0.42, n) * z
    y = rng.uniform(-0.32, 0.32, n) * z
    return np.stack([x, y, z], -1)


@pytest.mark.parametrize("name", DISTORTIONS)
def test_project_matches_opencv(name):
    dist = np.array(DISTORTIONS[name])
    X = _points()
    ref, _ = cv2.projectPoints(X, np.zeros(3), np.zeros(3), np.array(TABLE4_K), dist)
    got = project(jnp.asarray(X), _camera(dist))
    # float64 all the way: agreement to rounding.
    np.testing.assert_allclose(np.asarray(got), ref[:, 0], atol=1e-9)


@pytest.mark.parametrize("name", DISTORTIONS)
def test_undistort_matches_opencv_iterative(name):
    dist = np.array(DISTORTIONS[name])
    rng = np.random.default_rng(1)
    uv = np.stack([rng.uniform(0, 639, 500), rng.uniform(0, 479, 500)], -1)
    # cv2.undistortPoints stops after 5 iterations by default; ask for convergence.
    crit = (cv2.TERM_CRITERIA_COUNT | cv2.TERM_CRITERIA_EPS, 200, 1e-15)
    ref = cv2.undistortPoints(uv[:, None], np.array(TABLE4_K), dist, None, None, criteria=crit)[
        :, 0
    ]
    xy_d = (uv - [TABLE4_K[0][2], TABLE4_K[1][2]]) / [TABLE4_K[0][0], TABLE4_K[1][1]]
    got = undistort(jnp.asarray(xy_d), jnp.asarray(dist))
    np.testing.assert_allclose(np.asarray(got), ref, atol=1e-10)


@pytest.mark.parametrize("name", ["paper_table4", "pincushion"])
def test_round_trips(name):
    cam = _camera(DISTORTIONS[name])
    X = jnp.asarray(_points(seed=2))
    uv = project(X, cam)
    ray = pixel_to_ray(uv, cam)
    back = ray * (X[:, 2:] / ray[:, 2:])  # scale each ray to the true depth
    np.testing.assert_allclose(np.asarray(back), np.asarray(X), atol=1e-8)
    xy = jnp.asarray(np.random.default_rng(3).uniform(-0.35, 0.35, (300, 2)))
    np.testing.assert_allclose(
        np.asarray(undistort(distort(xy, cam.dist), cam.dist)), np.asarray(xy), atol=1e-11
    )


def test_jit_vmap_plain_agree():
    cam = _camera(TABLE4_DIST)
    X = jnp.asarray(_points(64, seed=4)).reshape(8, 8, 3)
    plain = project(X, cam)
    jitted = jax.jit(project)(X, cam)
    vmapped = jax.vmap(project, in_axes=(0, None))(X, cam)
    np.testing.assert_allclose(np.asarray(jitted), np.asarray(plain), atol=1e-12)
    np.testing.assert_allclose(np.asarray(vmapped), np.asarray(plain), atol=1e-12)
    uv = plain
    r_plain = pixel_to_ray(uv, cam)
    r_vmap = jax.vmap(pixel_to_ray, in_axes=(0, None))(uv, cam)
    r_jit = jax.jit(pixel_to_ray)(uv, cam)
    np.testing.assert_allclose(np.asarray(r_vmap), np.asarray(r_plain), atol=1e-12)
    np.testing.assert_allclose(np.asarray(r_jit), np.asarray(r_plain), atol=1e-12)


def test_gradients_finite_and_correct():
    cam = _camera(TABLE4_DIST)
    uv0 = jnp.array([[600.0, 40.0], [320.0, 240.0], [12.0, 460.0]])

    def f(uv, dist):
        c = Camera(cam.fx, cam.fy, cam.u0, cam.v0, dist, cam.image_size)
        return jnp.sum(pixel_to_ray(uv, c) ** 3)

    g_uv, g_dist = jax.grad(f, argnums=(0, 1))(uv0, cam.dist)
    assert np.all(np.isfinite(np.asarray(g_uv))) and np.all(np.isfinite(np.asarray(g_dist)))
    # Implicit gradient of the fixed point against central differences.
    eps = 1e-6
    for i in range(4):
        e = jnp.zeros(4).at[i].set(eps)
        fd = (f(uv0, cam.dist + e) - f(uv0, cam.dist - e)) / (2 * eps)
        np.testing.assert_allclose(float(g_dist[i]), float(fd), rtol=1e-5, atol=1e-8)
    e = jnp.zeros_like(uv0).at[0, 0].set(eps)
    fd = (f(uv0 + e, cam.dist) - f(uv0 - e, cam.dist)) / (2 * eps)
    np.testing.assert_allclose(float(g_uv[0, 0]), float(fd), rtol=1e-5, atol=1e-10)


def test_float32_follows_input():
    cam32 = Camera.from_matrix(
        np.array(TABLE4_K, np.float32), np.array(TABLE4_DIST, np.float32), (640, 480)
    )
    uv = jnp.array([[10.0, 20.0], [630.0, 470.0]], jnp.float32)
    ray = pixel_to_ray(uv, cam32)
    assert ray.dtype == jnp.float32
    cam64 = _camera(TABLE4_DIST)
    ref = pixel_to_ray(uv.astype(jnp.float64), cam64)
    np.testing.assert_allclose(np.asarray(ray), np.asarray(ref), atol=2e-6)
