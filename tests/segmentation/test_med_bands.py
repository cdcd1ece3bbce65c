"""Band MED for archives (`cslx.segmentation.med_bands`, issue 13) against full-frame MED.

Synthetic RGB crosses (a red horizontal and vertical stripe on a green-tinted, unevenly lit
background) with known sub-pixel centres; float32, as the command line runs it.
"""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np
import pytest

from cslx.segmentation import med_bands
from cslx.segmentation.med import med
from cslx.segmentation.steger import steger_centres

H, W = 240, 320


def cross_frame(seed, h_row=110.0, v_col=170.0, sigma=2.0):
    rng = np.random.default_rng(seed)
    rows, cols = np.arange(H)[:, None], np.arange(W)[None, :]
    hv = h_row + 0.03 * cols + 1.5 * np.sin(cols / 23 + seed)
    vu = v_col + 0.08 * rows + 1.5 * np.sin(rows / 19 + seed)
    red = 150 * np.exp(-0.5 * ((rows - hv) / sigma) ** 2)
    red += 150 * np.exp(-0.5 * ((cols - vu) / sigma) ** 2)
    red *= 1 + 0.2 * rng.standard_normal((H, W))
    light = 40 + 20 * np.cos(np.pi * rows / H) + 10 * (cols / W)
    rgb = np.stack([red + light, light + 5, light], -1) + 2 * rng.standard_normal((H, W, 3))
    return np.clip(rgb, 0, 255).astype(np.uint8), hv[0], vu[:, 0]


def full_frame_centres(rgb, axis):
    I = jnp.asarray(rgb[..., 0], jnp.float32) - jnp.asarray(rgb[..., 1], jnp.float32)
    return steger_centres(med(I, axis=axis).output, sigma=2.0, axis=axis)


def test_band_centres_agree_with_full_frame_med_and_warm_start_changes_nothing():
    made = [cross_frame(s) for s in (11, 12, 13)]
    frames = np.stack([f for f, _, _ in made])
    truths = [(h, v) for _, h, v in made]
    cfg = med_bands.BandConfig()
    flat = med_bands.initial_filters(cfg)
    filters, (rh, rv) = med_bands.extract_frames(frames, flat, cfg)
    assert np.all(np.asarray(rh.used_band)) and np.all(np.asarray(rv.used_band))
    for k in range(len(frames)):
        for axis, r in ((0, rh), (1, rv)):
            pos, valid = np.asarray(r.centres.pos[k]), np.asarray(r.centres.valid[k])
            full = full_frame_centres(frames[k], axis)
            both = valid & np.asarray(full.valid)
            assert both.mean() > 0.9
            assert abs(np.median(pos[both] - np.asarray(full.pos)[both])) < 0.05
            truth = truths[k][axis]
            assert np.median(np.abs(pos[valid] - truth[valid])) < 0.15
    # The same frames again from the carried filters: fewer steps, the same centres.
    _, (wh, wv) = med_bands.extract_frames(frames, filters, cfg)
    assert np.sum(np.asarray(wh.steps)) < np.sum(np.asarray(rh.steps))
    for a, b in ((rh, wh), (rv, wv)):
        ok = np.asarray(a.centres.valid & b.centres.valid)
        d = np.abs(np.asarray(a.centres.pos)[ok] - np.asarray(b.centres.pos)[ok])
        assert np.median(d) < 0.01


def test_stripes_that_do_not_fit_a_band_get_full_frame_med():
    rgb, _, _ = cross_frame(21)
    second, _, _ = cross_frame(22, h_row=30.0, v_col=40.0)
    both = np.maximum(rgb, second)  # two crosses: no band holds 90 % of the maxima
    cfg = med_bands.BandConfig()
    _, (rh, rv) = med_bands.extract_frames(both[None], med_bands.initial_filters(cfg), cfg)
    assert not bool(rh.used_band[0]) and not bool(rv.used_band[0])
    full = full_frame_centres(both, 0)
    np.testing.assert_array_equal(np.asarray(rh.centres.valid[0]), np.asarray(full.valid))


@pytest.mark.parametrize("seed", [4])
def test_a_two_lobed_band_filter_is_caught(seed):
    """A narrow stripe on 96 columns: linear-phase MED from the flat start converges to two
    lobes ±2–3 px apart and the band's centres jump; the check sends it to full-frame MED."""
    h, w = 160, 96
    truth = 70.0 + 0.137 * np.arange(w) + 2 * np.sin(np.arange(w) / 11)
    rng = np.random.default_rng(seed)
    rows = np.arange(h)[:, None]
    stripe = 100 * np.exp(-0.5 * ((rows - truth[None, :]) / 1.8) ** 2)
    stripe *= 1 + 0.3 * rng.standard_normal((h, w))
    light = 20 * (1 + 0.5 * np.cos(np.pi * rows / h))
    I = jnp.asarray(stripe + light + 0.5 * rng.standard_normal((h, w)), jnp.float32)
    cfg = med_bands.BandConfig()
    band = med(I[48:112], L=cfg.L, symmetric=True, max_steps=cfg.max_steps)
    c = steger_centres(band.output, sigma=2.0, axis=0)
    jump = np.median(np.abs(np.asarray(c.pos)[np.asarray(c.valid)] + 48 - truth[c.valid]))
    assert jump > 1.5  # the failure this guards against (if it stops failing, good)
    r = med_bands.band_centres(I, med_bands.initial_filters(cfg)[0], 0, cfg)
    assert not bool(r.used_band)
    ok = np.asarray(r.centres.valid)
    assert np.median(np.abs(np.asarray(r.centres.pos)[ok] - truth[ok])) < 0.15
