"""Steger's detector against SciPy's Gaussian derivatives and analytic stripes of known centre."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy import ndimage

from cslx.segmentation.steger import (
    Centres,
    gaussian_derivative,
    sigma_for_width,
    steger_centres,
    steger_cross,
)

H, W = 96, 160


def bar(v, centre, half_width):
    """Bright bar of half-width w sampled by pixel area along v (exact for any sub-pixel centre)."""
    lo = np.clip(v - 0.5, centre - half_width, centre + half_width)
    hi = np.clip(v + 0.5, centre - half_width, centre + half_width)
    return np.maximum(hi - lo, 0.0)


def gaussian(v, centre, s, slope=0.0):
    """Gaussian profile of std s across a stripe of the given slope dv/du (v-profile widened)."""
    return np.exp(-0.5 * (v - centre) ** 2 / (s**2 * (1.0 + slope**2)))


ROWS = np.arange(H, dtype=float)[:, None]
COLS = np.arange(W, dtype=float)


@pytest.mark.parametrize("order", [(0, 0), (1, 0), (0, 1), (2, 0), (1, 1), (0, 2)])
@pytest.mark.parametrize("sigma", [0.8, 2.0, 3.7])
def test_derivatives_match_scipy(order, sigma):
    # float64 sums of ≤ 31 taps: agreement to a few ulps of the data scale.
    img = np.random.default_rng(1).normal(size=(40, 57))
    ours = np.asarray(gaussian_derivative(jnp.asarray(img), sigma, order))
    ref = ndimage.gaussian_filter(img, sigma, order=order, mode="reflect", truncate=4.0)
    np.testing.assert_allclose(ours, ref, atol=1e-13, rtol=0)


@pytest.mark.parametrize("centre", [40.0, 40.13, 40.25, 40.37, 40.5, 40.62, 40.9])
@pytest.mark.parametrize("profile", ["gaussian", "bar"])
def test_straight_stripe_subpixel(centre, profile):
    # The Taylor step is exact up to ≈ d³/σ_tot² with d ≤ 0.5 px: < 0.02 px for σ_tot² ≥ 7.
    if profile == "gaussian":
        img, sigma = gaussian(ROWS, centre, 2.0) * np.ones(W), 2.0
    else:
        img, sigma = bar(ROWS, centre, 3.0) * np.ones(W), sigma_for_width(6.0)
    c = steger_centres(jnp.asarray(img), sigma=sigma)
    assert bool(np.all(c.valid))
    np.testing.assert_array_less(np.abs(np.asarray(c.pos) - centre), 0.02)


@pytest.mark.parametrize("slope", [0.0, 0.15, -0.3, 0.5])
def test_sloped_stripe(slope):
    centre = 47.3 + slope * (COLS - W / 2)
    img = gaussian(ROWS, centre, 2.0, slope)
    c = steger_centres(jnp.asarray(img), sigma=2.0)
    inner = slice(12, W - 12)  # the reflect boundary bends a sloped line near the border
    assert bool(np.all(np.asarray(c.valid)[inner]))
    err = np.abs(np.asarray(c.pos) - centre)[inner]
    assert err.max() < 0.02, err.max()


@pytest.mark.parametrize("profile", ["gaussian", "bar"])
def test_curved_stripe(profile):
    # v = 50 + 20 sin(u/50) + 0.3: curvature ≤ 0.008 /px. Smoothing a curved line moves its
    # ridge towards the centre of curvature by ≈ κ σ_tot²/4 (≤ 0.016 px here), which adds to the
    # Taylor error: mean < 0.02 px, worst column < 0.04 px.
    centre = 50.0 + 20.0 * np.sin(COLS / 50.0) + 0.3
    slope = 0.4 * np.cos(COLS / 50.0)
    if profile == "gaussian":
        img, sigma = gaussian(ROWS, centre, 2.0, slope), 2.0
    else:
        img, sigma = bar(ROWS, centre, 3.0 * np.sqrt(1 + slope**2)), sigma_for_width(6.0)
    c = steger_centres(jnp.asarray(img), sigma=sigma)
    inner = slice(12, W - 12)
    assert bool(np.all(np.asarray(c.valid)[inner]))
    err = np.abs(np.asarray(c.pos) - centre)[inner]
    assert err.mean() < 0.02 and err.max() < 0.04, (err.mean(), err.max())


def test_vertical_mode_is_transposed_horizontal():
    centre = 50.0 + 20.0 * np.sin(COLS / 50.0) + 0.3
    img = gaussian(ROWS, centre, 2.0) + 0.05 * np.random.default_rng(3).normal(size=(H, W))
    h = steger_centres(jnp.asarray(img), sigma=2.0, axis=0)
    v = steger_centres(jnp.asarray(img.T), sigma=2.0, axis=1)
    np.testing.assert_array_equal(np.asarray(h.valid), np.asarray(v.valid))
    np.testing.assert_allclose(np.asarray(h.pos), np.asarray(v.pos), atol=1e-12)
    np.testing.assert_allclose(np.asarray(h.strength), np.asarray(v.strength), atol=1e-12)


def test_cross_finds_both_stripes():
    hc, vc = 40.3, 97.6
    img = np.maximum(gaussian(ROWS, hc, 2.0) * np.ones(W), gaussian(COLS, vc, 2.0)[None, :])
    h, v = steger_cross(jnp.asarray(img), sigma=2.0)
    hu = np.abs(COLS - vc) > 10  # away from the crossing, where neither stripe is a line
    vr = np.abs(np.arange(H) - hc) > 10
    assert bool(np.all(np.asarray(h.valid)[hu])) and bool(np.all(np.asarray(v.valid)[vr]))
    assert np.abs(np.asarray(h.pos)[hu] - hc).max() < 0.02
    assert np.abs(np.asarray(v.pos)[vr] - vc).max() < 0.02
    # the single-stripe call ignores the other stripe's (steep) ridge points
    h1 = steger_centres(jnp.asarray(img), sigma=2.0, axis=0)
    assert np.abs(np.asarray(h1.pos)[hu] - hc).max() < 0.02


def test_threshold_rejects_empty_columns():
    img = gaussian(ROWS, 30.0, 2.0) * np.where(COLS < W / 2, 1.0, 0.0)
    img = img + 0.01 * np.random.default_rng(0).normal(size=img.shape)
    c = steger_centres(jnp.asarray(img), sigma=2.0, threshold=0.3)
    valid = np.asarray(c.valid)
    assert valid[5 : W // 2 - 8].all() and not valid[W // 2 + 8 :].any()
    assert np.isnan(np.asarray(c.pos)[~valid]).all()
    assert np.all(np.asarray(c.strength)[~valid] == 0)
    none = steger_centres(jnp.asarray(img), sigma=2.0, min_strength=10.0)
    assert not np.asarray(none.valid).any()


def test_jit_vmap_plain_agree_and_float32():
    rng = np.random.default_rng(5)
    frames = np.stack(
        [gaussian(ROWS, 30.0 + 7.3 * k, 2.0) + 0.05 * rng.normal(size=(H, W)) for k in range(3)]
    )
    plain = [steger_centres(jnp.asarray(f), sigma=2.0) for f in frames]
    batched = jax.vmap(lambda f: steger_centres(f, sigma=2.0))(jnp.asarray(frames))
    jitted = jax.jit(lambda f: steger_centres(f, sigma=2.0))
    for k, p in enumerate(plain):
        np.testing.assert_array_equal(np.asarray(batched.valid[k]), np.asarray(p.valid))
        np.testing.assert_allclose(np.asarray(batched.pos[k]), np.asarray(p.pos), atol=1e-12)
        np.testing.assert_allclose(np.asarray(jitted(frames[k]).pos), np.asarray(p.pos), atol=1e-12)
    c32 = steger_centres(jnp.asarray(frames[0], jnp.float32), sigma=2.0)
    assert c32.pos.dtype == jnp.float32
    both = np.asarray(c32.valid) & np.asarray(plain[0].valid)
    assert both.mean() > 0.95
    # float32 derivative sums: ≈ 1e-6 relative, amplified by 1/λ in the offset
    np.testing.assert_allclose(np.asarray(c32.pos)[both], np.asarray(plain[0].pos)[both], atol=1e-3)


def test_gradient_wrt_image_is_finite_and_matches_finite_differences():
    img = gaussian(ROWS[:40], 20.3 + 0.1 * np.sin(COLS[:48] / 7.0), 2.0)
    img = jnp.asarray(img)

    def loss(x):
        c = steger_centres(x, sigma=2.0)
        return jnp.sum(jnp.where(c.valid, c.pos, 0.0) ** 2)

    g = jax.grad(loss)(img)
    assert bool(jnp.all(jnp.isfinite(g)))
    assert float(jnp.abs(g).max()) > 0
    direction = jnp.asarray(np.random.default_rng(2).normal(size=img.shape))
    eps = 1e-6
    fd = (loss(img + eps * direction) - loss(img - eps * direction)) / (2 * eps)
    np.testing.assert_allclose(float(jnp.vdot(g, direction)), float(fd), rtol=1e-5)


def test_bad_input():
    with pytest.raises(ValueError, match="2-D"):
        steger_centres(jnp.zeros((3, 4, 3)), sigma=1.0)
    with pytest.raises(ValueError, match="axis"):
        steger_centres(jnp.zeros((8, 8)), sigma=1.0, axis=2)
    with pytest.raises(ValueError, match="width"):
        sigma_for_width(0.0)
    assert isinstance(steger_centres(np.zeros((8, 8), np.uint8), sigma=1.0), Centres)


def test_snr_floor_rejects_noise_only_frames():
    rng = np.random.default_rng(7)
    noise = rng.normal(0.0, 5.0, size=(H, W))
    empty = steger_centres(jnp.asarray(noise), sigma=2.0)
    assert np.asarray(empty.valid).mean() < 0.03
    stripe = steger_centres(jnp.asarray(noise + 60.0 * gaussian(ROWS, 44.2, 2.0)), sigma=2.0)
    assert np.asarray(stripe.valid).mean() > 0.95


@pytest.mark.parametrize("shape", [(64, 640), (480, 128), (9, 23)])
@pytest.mark.parametrize("sigma", [0.8, 2.0])
def test_hessian_from_one_2d_pad_equals_padding_each_pass(shape, sigma):
    # _ridge pads the image once in both axes (issue 13); padding each separable pass on
    # its own (the old formulation) gives the same derivatives to float32 rounding (XLA
    # contracts the sums into FMAs differently in the two programs: a few ulps).
    from cslx.segmentation.steger import _filter_axis, _filter_padded, _radius

    rng = np.random.default_rng(shape[0])
    rows = np.arange(shape[0], dtype=float)[:, None]
    stripe = 200.0 * gaussian(rows, 0.4 * shape[0] + 0.1 * np.arange(shape[1]) % 7, 2.0)
    image = jnp.asarray(stripe + rng.normal(0.0, 5.0, shape), jnp.float32)

    def old(img):
        a0, a1, a2 = _filter_axis(img, sigma, (0, 1, 2), 0)
        return (
            *_filter_axis(a0, sigma, (1, 2), 1),
            *_filter_axis(a1, sigma, (0, 1), 1),
            *_filter_axis(a2, sigma, (0,), 1),
        )

    def new(img):
        r = _radius(sigma)
        a0, a1, a2 = _filter_padded(jnp.pad(img, r, mode="symmetric"), sigma, (0, 1, 2), 0)
        return (
            *_filter_padded(a0, sigma, (1, 2), 1),
            *_filter_padded(a1, sigma, (0, 1), 1),
            *_filter_padded(a2, sigma, (0,), 1),
        )

    if min(shape) > 2 * _radius(sigma):
        for a, b in zip(jax.jit(old)(image), jax.jit(new)(image), strict=True):
            scale = float(jnp.max(jnp.abs(a)))
            np.testing.assert_allclose(np.asarray(b), np.asarray(a), rtol=1e-5, atol=1e-6 * scale)
