"""Speckle-weighted profile fit (cslx.segmentation.profile)."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from cslx.segmentation.profile import fit_centres
from cslx.segmentation.refine import refine_centres


def _stripe(truth, h=64, s=1.8, amp=200.0, slope=0.0, noise=None):
    """(H, W) horizontal stripe: background 20 + slope·(v − 32), Gaussian of std s."""
    v = np.arange(h, dtype=float)[:, None]
    g = amp * np.exp(-0.5 * ((v - truth[None, :]) / s) ** 2)
    if noise is not None:
        g = g * noise
    return (20.0 + slope * (v - 32.0) + g).astype(np.float32)


def _fit(image, start, exclude=None, half=12):
    n = image.shape[1]
    ex = np.zeros(image.shape, bool) if exclude is None else exclude
    return [
        np.asarray(a)
        for a in fit_centres(
            jnp.asarray(image),
            jnp.asarray(start, jnp.float32),
            jnp.ones(n, bool),
            jnp.asarray(ex),
            jnp.float32(1.0),
            half=half,
            axis=0,
        )
    ]


def test_fit_ignores_a_background_slope_across_the_stripe():
    truth = 31.3 + 0.01 * np.arange(200)
    image = _stripe(truth, slope=6.0)  # 6 DN/px under a 200 DN stripe
    pos, found, sd, chi2 = _fit(image, truth + 0.3)
    assert found.all() and np.isfinite(sd).all()
    assert np.abs(pos - truth).max() < 0.01
    # the Gaussian derivative's zero crossing is pulled up the slope (Steger 1998 §4)
    der, _ = refine_centres(
        jnp.asarray(image),
        jnp.asarray(truth + 0.3, jnp.float32),
        jnp.ones(len(truth), bool),
        sigma=2.5,
        sigma_along=0.0,
        axis=0,
    )
    assert np.abs(np.mean(np.asarray(der) - truth)) > 0.1


def test_fit_beats_the_derivative_under_multiplicative_noise():
    rng = np.random.default_rng(3)
    w = 2000
    truth = 31.0 + (0.013 * np.arange(w)) % 1.0
    speckle = rng.gamma(4.0, 0.25, size=(64, w))  # unit mean, contrast 0.5
    image = _stripe(truth, noise=speckle) + rng.normal(0.0, 1.5, (64, w)).astype(np.float32)
    start = jnp.asarray(truth, jnp.float32)
    pos, found, _, chi2 = _fit(image, truth)
    der, ok = refine_centres(
        jnp.asarray(image), start, jnp.ones(w, bool), sigma=2.5, sigma_along=0.0, axis=0
    )
    e_fit = (pos - truth)[found]
    e_der = (np.asarray(der) - truth)[np.asarray(ok)]
    assert found.mean() > 0.99
    assert np.std(e_fit) < 0.8 * np.std(e_der)
    assert abs(np.mean(e_fit)) < 0.02
    assert np.median(chi2[found]) < 3.0


def test_clipped_pixels_get_no_weight():
    truth = 30.6 + 0.02 * np.arange(120)
    image = _stripe(truth, s=2.2, amp=600.0)
    clipped = image >= 255.0
    image = np.minimum(image, 255.0)
    assert clipped.any(axis=0).all()
    pos, found, _, _ = _fit(image, truth + 0.4, exclude=clipped, half=16)
    assert found.all()
    assert np.abs(pos - truth).max() < 0.02
