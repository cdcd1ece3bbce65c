"""Smoke and correctness tests of experiments/tune_differentiable.py on a small synthetic crop.

The crop is drawn analytically (no renderer): a red laser stripe with a Gaussian profile
(std 2 px) along a known smooth curve v*(u), on a grey, sunlit background with noise. Its
ground-truth 3-D points are the triangulation of (u, v*(u)) on the true plane 0, so the
surrogate's loss is exactly the 3-D error of its centres.
"""

from __future__ import annotations

import math

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.segmentation.steger import steger_centres  # noqa: E402
from cslx.sensor import default_sensor, triangulate  # noqa: E402
from experiments import tune_differentiable as T

H, W = 64, 96
ORIGIN = (280.0, 200.0)  # (u0, v0) of the crop in the 640×480 frame


def _crop(seed: int = 0):
    rng = np.random.default_rng(seed)
    u = np.arange(W, dtype=float)
    v_true = 30.0 + 6.0 * np.sin(2 * np.pi * u / 80.0) + 0.03 * u
    v = np.arange(H, dtype=float)[:, None]
    laser = 200.0 * np.exp(-0.5 * ((v - v_true[None, :]) / 2.0) ** 2)
    sun = 60.0 * np.exp(-0.5 * ((v - 10.0) / 6.0) ** 2) * (u[None, :] > 40)  # grey glare band
    rgb = np.stack([30 + sun + laser, 30 + sun + 0.07 * laser, 30 + sun + 0.04 * laser], -1)
    rgb = np.clip(rgb + rng.normal(0, 2.0, rgb.shape), 0, 255).round().astype(np.uint8)
    sensor = default_sensor(jnp.float64)
    uv = np.stack([u + ORIGIN[0], v_true + ORIGIN[1]], -1)
    gt_h = np.asarray(triangulate(sensor, jnp.asarray(uv), 0))
    gt_v = np.full((H, 3), np.nan)  # no vertical stripe in the crop
    return rgb, v_true, gt_h, gt_v, sensor


def _cfg(**kw):
    # One unrolled MED step keeps the compiled graph (and the test) small.
    # Taps radius 10 is exact enough for σ ≲ 2.5 (4σ support), which these tests stay at.
    return dict(T.CONFIG, stripes=("h",), med_steps=1, taps_radius=10, origin=ORIGIN, **kw)


def test_soft_centre_matches_hard_steger():
    """The softmax centre agrees with Steger's hard centre (and the truth) on a clean stripe."""
    rgb, v_true, *_ = _crop()
    I = jnp.asarray(rgb[..., 0], jnp.float64) - jnp.asarray(rgb[..., 1], jnp.float64)
    radius = math.ceil(4 * T.SIGMA_RANGE[1])
    soft_fn = jax.jit(T.soft_centres, static_argnums=(2, 3, 4))
    soft = np.asarray(soft_fn(I, jnp.float64(2.0), 0, 0.03, radius))
    hard = steger_centres(I, sigma=2.0, axis=0)
    ok = np.asarray(hard.valid)
    assert ok.mean() > 0.9
    # Tolerance: the softmax mixes in the ridge's neighbours, whose Taylor offsets are a few
    # hundredths of a pixel off; the true centre itself is within the noise (~0.05 px).
    assert np.max(np.abs(soft[ok] - np.asarray(hard.pos)[ok])) < 0.05
    assert np.median(np.abs(soft - v_true)) < 0.1


def test_surrogate_gradient_matches_finite_differences():
    """jax.grad of the surrogate loss (unrolled MED → soft Steger → triangulation) in σ and
    the loading equals central finite differences (float64), and the colour-weight gradient
    is finite and tangent to the sphere (scale invariance)."""
    rgb, _, gt_h, gt_v, sensor = _crop()
    cfg = _cfg()
    images = jnp.asarray(rgb[None], jnp.float64)
    gts = {"h_xyz": jnp.asarray(gt_h[None]), "v_xyz": jnp.asarray(gt_v[None])}
    theta = jnp.asarray(T.pack((1.0, -1.0, 0.0), 2.0, 1e-3))

    def f(th):
        return T.surrogate_loss(th, images, gts, sensor, cfg)

    vg = jax.jit(jax.value_and_grad(f))  # one compile serves the differences too
    val, grad = vg(theta)
    grad = np.asarray(grad)
    # One unrolled MED step from the flat start is far from converged: ~1 mm, not ~0.1.
    assert np.isfinite(val) and 0 < float(val) < 5.0
    assert np.all(np.isfinite(grad))
    for i, h in ((3, 1e-4), (4, 1e-4)):
        e = np.zeros(5)
        e[i] = h
        fd = (float(vg(theta + e)[0]) - float(vg(theta - e)[0])) / (2 * h)
        # Relative 1e-3 (+ absolute floor): central differences of a float64 function whose
        # curvature scale in these coordinates is O(1).
        assert abs(grad[i] - fd) <= 1e-3 * abs(fd) + 1e-6, (i, grad[i], fd)
    w = np.asarray(theta[:3])
    assert abs(grad[:3] @ w) <= 1e-8 * np.linalg.norm(grad[:3]) * np.linalg.norm(w) + 1e-12


@pytest.mark.parametrize("steps", [2])
def test_train_smoke(steps):
    """Two BFGS steps run, record a history and never end above the starting loss."""
    rgb, _, gt_h, gt_v, sensor = _crop(1)
    cfg = _cfg(bfgs_steps=steps)
    theta, history = T.train(
        rgb[None], {"h_xyz": gt_h[None], "v_xyz": gt_v[None]}, sensor, cfg, log=lambda s: None
    )
    assert theta.shape == (5,) and np.all(np.isfinite(theta))
    assert 1 < len(history) <= steps + 1
    losses = [h["loss_accepted"] for h in history]
    assert np.all(np.isfinite(losses))
    assert losses[-1] <= losses[0] + 1e-6
    settings = T._settings(theta)
    assert abs(np.linalg.norm(settings["weights"]) - 1) < 1e-5
    assert T.SIGMA_RANGE[0] < settings["sigma"] < T.SIGMA_RANGE[1]
