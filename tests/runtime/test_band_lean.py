"""Bands that follow a leaning stripe (issues 12 / 13, `cslx.runtime.band_lean`)."""

import dataclasses

import jax
import jax.numpy as jnp
import numpy as np

from cslx.runtime import band_lean
from cslx.runtime.band_input import frame_input, rgb_cutter
from cslx.runtime.band_lean import lean_starts, stripe_line
from cslx.runtime.pipeline import PipelineConfig, _bands, init_state
from cslx.segmentation.steger import Centres, steger_centres

W = (1.0, -1.0, 0.0)
H_, W_ = 240, 320
next_bands = jax.jit(band_lean.next_bands, static_argnums=(3, 4))


def _leaning_cross(slope_h=0.25, slope_v=-0.3, seed=0):
    """Grey noisy frame with a red stripe v = 100 + slope_h·u and one u = 150 + slope_v·v
    (Gaussian profiles, σ 1.6 px, the horizontal one clipped in R over its core)."""
    rng = np.random.default_rng(seed)
    v, u = np.mgrid[0:H_, 0:W_].astype(float)
    dh = (v - 100 - slope_h * u) / np.hypot(1, slope_h)
    dv = (u - 150 - slope_v * v) / np.hypot(1, slope_v)
    red = 40 + 260 * np.exp(-0.5 * (dh / 1.6) ** 2) + 180 * np.exp(-0.5 * (dv / 1.6) ** 2)
    rgb = np.stack([red, np.full_like(red, 40), np.full_like(red, 40)], -1)
    rgb += rng.normal(0, 2, rgb.shape)
    return jnp.asarray(np.clip(rgb, 0, 255).astype(np.uint8))


def _centres(pos, valid):
    pos = jnp.asarray(pos, jnp.float32)
    return Centres(jnp.where(valid, pos, jnp.nan), jnp.asarray(valid), jnp.ones_like(pos))


def test_stripe_line_ignores_stray_centres():
    u = np.arange(320.0)
    pos = 100 + 0.4 * u
    pos[::40] = 5.0  # the other stripe, a glint
    a, b = stripe_line(jnp.asarray(pos, jnp.float32), jnp.ones(320, bool), 24.0)
    assert abs(float(a) - 100) < 1e-3 and abs(float(b) - 0.4) < 1e-5


def test_next_bands_straight_when_it_fits_sheared_when_it_leans():
    config = PipelineConfig(roi_half_h=16, roi_half_w=24)
    state = init_state(config, (W_, H_))
    u, v = np.arange(W_), np.arange(H_)
    vertical = _centres(150 + 0.02 * v, np.ones(H_, bool))
    flat = next_bands(
        _centres(100 + 0.02 * u, np.ones(W_, bool)), vertical, state, config, (H_, W_)
    )
    assert bool(flat.tracking) and int(flat.row0) == 87 and np.all(np.asarray(flat.lean_h) == 0)
    lean = next_bands(_centres(10 + 0.3 * u, np.ones(W_, bool)), vertical, state, config, (H_, W_))
    assert bool(lean.tracking) and abs(float(lean.lean_h[1]) - 0.3) < 1e-6
    s = np.asarray(lean_starts(lean.lean_h, W_, H_, 32))
    np.testing.assert_allclose(s[30:], 10 + 0.3 * u[30:] - 16, atol=1e-3)
    assert np.all(s[:20] == 0)  # clamped to the frame
    # a stripe bent by more than the band: no tracking, straight bands for the first pass
    bent = _centres(100 + 60 * np.sin(u / 40.0), np.ones(W_, bool))
    lost = next_bands(bent, vertical, state, config, (H_, W_))
    assert not bool(lost.tracking) and np.all(np.asarray(lost.lean_h) == 0)
    # off: the leaning stripe ends tracking
    off = dataclasses.replace(config, roi_lean=False)
    assert not bool(
        next_bands(
            _centres(60 + 0.3 * u, np.ones(W_, bool)), vertical, state, off, (H_, W_)
        ).tracking
    )


def test_sheared_bands_agree_with_full_frame_centres():
    """Steger in the sheared bands (cut from the RGB frame, interpolated between rows)
    finds the full frame's centres of both leaning stripes, except where the other stripe
    crosses (it leans otherwise in the sheared band) and within 4σ of the frame's ends
    (the reflect padding there kinks the leaning stripe of the full frame, not the band's)."""
    rgb = _leaning_cross()
    config = PipelineConfig(roi_half_h=16, roi_half_w=24, use_med=False)
    I_h, I_v = frame_input(rgb, W, jnp.float32)
    full_h = steger_centres(I_h, sigma=config.sigma, axis=0, snr=config.snr)
    full_v = steger_centres(I_v, sigma=config.sigma, axis=1, snr=config.snr)
    state = next_bands(full_h, full_v, init_state(config, (W_, H_)), config, (H_, W_))
    assert bool(state.tracking) and float(state.lean_h[1]) != 0 and float(state.lean_v[1]) != 0

    @jax.jit
    def bands(rgb, state):
        return _bands(rgb_cutter(rgb, W, jnp.float32), (H_, W_), state, config)[:2]

    got = bands(rgb, state)
    for axis, full, other, band in zip(
        (0, 1), (full_h, full_v), (full_v, full_h), got, strict=True
    ):
        pos = np.asarray(full.pos)
        index = np.arange(len(pos))
        ok = np.asarray(other.valid)
        b, a = np.polyfit(np.flatnonzero(ok), np.asarray(other.pos)[ok], 1)
        crossing = np.abs(index - (a + b * pos)) < 12
        ends = (index < 4 * config.sigma) | (index >= len(pos) - 4 * config.sigma)
        away = ~crossing & ~ends
        assert away.mean() > 0.8
        both = np.asarray(full.valid) & np.asarray(band.valid)
        assert both.sum() >= 0.97 * np.asarray(full.valid).sum()
        d = np.abs(np.asarray(band.pos) - pos)[both & away]
        assert np.median(d) < 0.01 and d.max() < 0.05, (axis, np.median(d), d.max())
