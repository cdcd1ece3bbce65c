"""The tracker's colour-weight check (`cslx.runtime.stripe_colour`) on synthetic crosses."""

import numpy as np
import pytest

from cslx.runtime.stripe_colour import CANDIDATES, choose_weights, search

R_G = (1.0, -1.0, 0.0)


def _cross(laser_rgb, power=150.0, seed=0):
    """A cross of Gaussian profiles (std 2 px) in colour `laser_rgb` on a noisy grey plate."""
    v, u = np.mgrid[0:480, 0:640].astype(float)
    laser = np.maximum(np.exp(-0.5 * ((v - 200.3) / 2) ** 2), np.exp(-0.5 * ((u - 350.6) / 2) ** 2))
    img = 60 + power * laser[..., None] * np.asarray(laser_rgb)
    img += np.random.default_rng(seed).normal(0, 2.0, img.shape)
    return np.clip(np.round(img), 0, 255).astype(np.uint8)


def test_grid_is_the_papers():
    assert CANDIDATES.shape == (74, 3)


def test_red_keeps_r_minus_g():
    weights, why = choose_weights(_cross((1.0, 0.07, 0.04)), R_G)
    assert weights == R_G and why.startswith("kept")


@pytest.mark.parametrize(
    "laser, bright", [((0.12, 1.0, 0.2), 1), ((0.04, 0.18, 1.0), 2)], ids=["green", "blue"]
)
def test_other_lasers_get_a_bright_space(laser, bright):
    img = _cross(laser)
    weights, why = choose_weights(img, R_G)
    assert weights != R_G and "R" not in why[:1]
    # the chosen space makes the laser's own channel count most: the stripe is bright
    assert int(np.argmax(weights)) == bright, weights
    assert np.dot(weights, laser) > 0


def test_no_stripe_keeps_the_configured_weights():
    flat = np.random.default_rng(1).normal(80, 2.0, (480, 640, 3)).clip(0, 255).astype(np.uint8)
    weights, _ = choose_weights(flat, R_G)
    assert weights == R_G


def test_search_signs_the_space_bright():
    weights, score = search(_cross((0.12, 1.0, 0.2)))
    assert weights[1] > 0 and score > 10


def test_near_clipped_jpeg_core_is_left_out_of_the_moments():
    """A JPEG-compressed clipped core sits at 251–255 with smeared green and blue: every pixel
    with a channel ≥ `SEARCH_CLIP_LEVEL` (240) is replaced by the frame's median colour, as
    in the extractor's search; a bright but unclipped stripe pixel is kept."""
    from cslx.config import SEARCH_CLIP_LEVEL
    from cslx.runtime.stripe_colour import _segments

    img = np.full((480, 640, 3), 60, np.uint8)
    img[:, 0] = (252, 246, 244)  # column 0 is sampled (every 8th column)
    img[:, 8] = (230, 100, 90)
    seg = _segments(img, axis=0)  # (rows, sampled columns, 3)
    assert SEARCH_CLIP_LEVEL == 240.0
    np.testing.assert_array_equal(seg[:, 0], np.full((480, 3), 60.0))
    np.testing.assert_array_equal(seg[:, 1], np.tile([230.0, 100.0, 90.0], (480, 1)))
