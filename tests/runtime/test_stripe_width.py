"""Steger's σ from the stripe's measured width (`cslx.runtime.stripe_width`), in the tracker."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.runtime.stripe_width import (
    FWHM_PER_STD,
    choose_sigma,
    frame_sigma,
    stripe_widths,
    with_frame_sigma,
)
from cslx.runtime.tracker import Tracker, tracking_config
from cslx.sensor import default_sensor


def _cross(s_h, s_v, shape=(480, 640), clip=False, seed=0):
    """A red cross of Gaussian profiles (std s_h, s_v px) on a noisy grey plate."""
    h, w = shape
    v, u = np.mgrid[0:h, 0:w].astype(float)
    laser = np.maximum(
        np.exp(-0.5 * ((v - 200.3) / s_h) ** 2), np.exp(-0.5 * ((u - 350.6) / s_v) ** 2)
    )
    red = 60 + (600 if clip else 150) * laser
    img = np.stack([red, 60 + 0.07 * (red - 60), np.full_like(red, 55)], -1)
    img += np.random.default_rng(seed).normal(0, 2.0, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


@pytest.mark.parametrize("s", [1.0, 2.0, 3.2, 6.0])
def test_widths_of_gaussian_stripes(s):
    wh, wv = stripe_widths(_cross(s, 1.5 * s), (1.0, -1.0, 0.0))
    assert wh == pytest.approx(FWHM_PER_STD * s, rel=0.08, abs=0.3)
    assert wv == pytest.approx(FWHM_PER_STD * 1.5 * s, rel=0.08, abs=0.3)


def test_clipped_core_counts_as_the_peak():
    # a core clipped to white is 0 in R − G: the plateau still makes the stripe wide
    wh, _ = stripe_widths(_cross(3.0, 3.0, clip=True), (1.0, -1.0, 0.0))
    assert wh > FWHM_PER_STD * 3.0


def test_no_stripe_keeps_the_floor():
    flat = np.full((480, 640, 3), 80, np.uint8)
    assert all(np.isnan(stripe_widths(flat, (1.0, -1.0, 0.0))))
    assert choose_sigma(np.nan, 2.0) == 2.0
    assert choose_sigma(4.6, 2.0) == 2.0  # the default rig's clean stripe (s ≈ 1.95 px)
    assert choose_sigma(7.9, 2.0) == 2.0  # its widest sunny, clipped stripe: kept (SWITCH)
    assert choose_sigma(10.4, 2.0) == 4.5  # the 1.6× lens in sun
    assert choose_sigma(40.0, 2.0) == 6.0 and choose_sigma(40.0, 3.0, 720) == 9.0


def test_with_frame_sigma_undoes_the_frame_scaling():
    config = tracking_config()
    assert with_frame_sigma(config, 2.0, 480, 640) is config
    assert frame_sigma(with_frame_sigma(config, 4.5, 720, 1280), 720, 1280) == pytest.approx(4.5)
    assert frame_sigma(with_frame_sigma(config, 3.0, 480, 640), 480, 640) == 3.0


def _lens_sensor(f=1.6):
    from cslx.sensor.camera import Camera

    s = default_sensor(jnp.float32)
    c = s.camera
    return eqx.tree_at(
        lambda x: x.camera, s, Camera(c.fx * f, c.fy * f, c.u0, c.v0, c.dist, c.image_size)
    )


def test_tracker_sigma_follows_a_longer_lens():
    """Rig audit (`cslx.runtime.stripe_width`): a 640×480 camera with a 1.6× longer lens sees
    the stripes 1.6× wider; at the fixed σ 2 this sunny T frame (audit seed 8803) gave
    33 / 13 gross (> 1 mm) centres on the horizontal / vertical stripe."""
    from cslx.runtime.band_input import frame_input
    from cslx.segmentation import stripe_point_errors
    from cslx.segmentation.steger import steger_centres
    from cslx.sim import NUISANCES, random_pose, random_world, render_frame

    sensor = _lens_sensor()
    rng = np.random.default_rng(8803)
    world = random_world("cross", rng)
    pose = random_pose(world, "cross", rng, sensor)
    img, gt = render_frame(sensor, world, pose, NUISANCES["sunny"], 88030, scene_seed=8803)
    lines = []
    tracker = Tracker(sensor, log=lines.append)
    assert tracker.sigma == 2.0
    obs = [tracker.step(img, odometry=0.0) for _ in range(3)]
    assert tracker.sigma >= 4.0 and min(tracker.stripe_width_px) > 8.0
    assert all(o.status == "ok" for o in obs)
    # σ is chosen once: two programs (start-up, the measured σ), none per frame
    assert sum("compiled" in line for line in lines) == 2
    tracker.reset()  # measured again on the next frame; the program is reused, not rebuilt
    tracker.step(img)
    assert tracker.sigma >= 4.0 and sum("compiled" in line for line in lines) == 2

    # The pipeline's centres are Steger's on the filled R − G image (no MED in the tracker):
    # at σ 2 many are gross, at the measured σ none or almost none.
    config = tracker.config
    fill = jax.jit(frame_input, static_argnums=(1, 2, 3))
    images = fill(jnp.asarray(img), config.weights, jnp.float32, True)
    gross = {}
    for sigma in (2.0, tracker.sigma):
        for axis, key in ((0, "h_xyz"), (1, "v_xyz")):
            c = steger_centres(
                images[axis], sigma=sigma, axis=axis, threshold=config.threshold, snr=config.snr
            )
            pos = np.where(np.asarray(c.valid), np.asarray(c.pos, float), np.nan)
            idx = np.arange(len(pos), dtype=float)
            uv = np.stack([idx, pos] if axis == 0 else [pos, idx], -1)
            err, _, n_gt, _ = stripe_point_errors(uv, gt[key], sensor, axis)
            gross[sigma, axis] = int(np.sum(err > 1.0))
            if sigma > 2.0:
                assert len(err) > 0.9 * n_gt and np.median(err) < 0.1
    assert gross[2.0, 0] + gross[2.0, 1] >= 10, gross
    assert max(gross[tracker.sigma, 0], gross[tracker.sigma, 1]) <= 2, gross
