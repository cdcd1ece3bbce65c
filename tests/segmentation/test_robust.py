"""The robust detector's pieces (cslx.segmentation.robust / ridges): column profiles at the
crossing, bridging a clipped crossing, detours, float32 path residuals, the moment-based
kurtosis grid."""

from __future__ import annotations

import jax.numpy as jnp
import numpy as np

from cslx.segmentation import extract
from cslx.segmentation.colour import CANDIDATES, search_space
from cslx.segmentation.ridges import _drop_detours, _local_residual, linked_centres
from cslx.segmentation.search import _grid_scores

H, W = 120, 200


def _cross(rng, tilt=0.04, noise=2.0):
    """A horizontal Gaussian stripe (s 1.2 px) crossed by a brighter vertical one (s 1.5 px)."""
    u = np.arange(W)
    v_true = 60.3 + tilt * (u - 100)
    vv, uu = np.arange(H)[:, None], u[None, :]
    img = 20.0 + 120.0 * np.exp(-0.5 * ((vv - v_true[None, :]) / 1.2) ** 2)
    img = img + 200.0 * np.exp(-0.5 * ((uu - 120.4 - 0.02 * vv) / 1.5) ** 2)
    return img + rng.normal(0, noise, img.shape), v_true


def test_column_profiles_measure_through_the_crossing():
    rng = np.random.default_rng(11)
    img, v_true = _cross(rng)
    c, _ = linked_centres(img, sigma=2.0, sigma_along=4.0)
    pos = np.asarray(c.pos)
    near = np.abs(np.arange(W) - 120) <= 6  # the other stripe's core and flanks
    assert np.isfinite(pos[near]).all()
    # A tilted straight stripe has a symmetric column profile: no bias from the crossing
    # stripe, which is (nearly) constant along the column. Tolerance: 5 noise std.
    err = np.abs(pos - v_true)
    assert err[near].max() < 0.15
    assert np.nanmax(err[4:-4]) < 0.15


def test_local_residual_stays_exact_far_from_column_zero_in_float32():
    n = 640
    x = np.arange(n)
    pos = (200.0 + 0.37 * x).astype(np.float32)
    pos[600] += 2.0
    r = np.asarray(_local_residual(jnp.asarray(pos), jnp.ones(n, bool), 6))
    assert abs(r[600] - 2.0) < 1e-3
    others = np.abs(np.delete(r, np.arange(594, 607)))
    assert others.max() < 1e-3  # global sums of x² in float32 were off by pixels here


def test_short_detours_are_dropped_long_pieces_kept():
    n = 200
    pos = 50.0 + 0.1 * np.arange(n)
    valid = np.ones(n, bool)
    valid[80:86] = False
    valid[92:100] = False
    pos[86:92] += 20.0  # six centres on something else between two gaps
    out = np.asarray(_drop_detours(jnp.asarray(pos), jnp.asarray(valid)))
    assert not out[86:92].any()
    assert out[:80].all() and out[100:].all()
    # The same piece on the line stays.
    pos[86:92] -= 20.0
    out = np.asarray(_drop_detours(jnp.asarray(pos), jnp.asarray(valid)))
    assert out[86:92].all()


def _clipped_cross(rng):
    """Red horizontal stripe clipped in R over ≈ 6 px, crossed by a vertical stripe whose
    core is white (every channel clipped) over ≈ 9 columns."""
    vv, uu = np.arange(H)[:, None].astype(float), np.arange(W)[None, :].astype(float)
    v_true = 60.37 + 0.03 * (np.arange(W) - 100)
    h = np.exp(-0.5 * ((vv - v_true[None, :]) / 2.5) ** 2)
    v = np.exp(-0.5 * ((uu - 110.2) / 3.0) ** 2) * np.ones((H, 1))
    r = 40 + 700 * h + 2000 * v
    g = 38 + 40 * h + 2000 * v
    b = 38 + 25 * h + 2000 * v
    rgb = np.stack([r, g, b], -1) + rng.normal(0, 1.5, (H, W, 3))
    return np.clip(np.round(rgb), 0, 255).astype(np.uint8), v_true


def test_stretch_hidden_by_a_clipped_crossing_is_bridged_and_flagged():
    rng = np.random.default_rng(12)
    rgb, v_true = _clipped_cross(rng)
    white = (rgb >= 254).all(-1).all(0)
    assert white.sum() >= 6  # columns with no information on the horizontal stripe
    c = extract(rgb, "linked", space="r-g", stripe="h")
    pos, sat = np.asarray(c.pos), np.asarray(c.saturated)
    assert np.isfinite(pos[white]).all()
    assert sat[white].all()
    assert np.abs(pos[white] - v_true[white]).max() < 0.3
    sig = np.asarray(c.sigma)
    assert np.isfinite(sig[white]).all() and (sig[white] > 0).all()
    # Away from the crossing the (R-clipped, filled) core is measured.
    far = np.abs(np.arange(W) - 110) > 30
    assert np.isfinite(pos[far]).mean() > 0.95
    assert np.nanmedian(np.abs(pos[far] - v_true[far])) < 0.1
    # The same frame as a 16-bit file holds it: the same centres and clipped flags (a uint16
    # frame was taken as 8-bit, every pixel above the clip level, and gave no centre at all).
    c16 = extract(rgb.astype(np.uint16) * 257, "linked", space="r-g", stripe="h")
    np.testing.assert_allclose(np.asarray(c16.pos), pos, atol=1e-4)
    assert np.array_equal(np.asarray(c16.saturated), sat)


def test_moment_grid_scores_equal_the_direct_search():
    rng = np.random.default_rng(13)
    img, _ = _cross(rng)
    sun = rng.uniform(40, 120, (H, W))[..., None] * np.array([1.0, 0.97, 0.93])
    rgb = sun + img[..., None] * np.array([1.0, 0.07, 0.04]) + rng.normal(0, 2, (H, W, 3))
    rgb = jnp.asarray(rgb)  # float64 under the test configuration
    _, direct = search_space(rgb, axis=0)
    moments = _grid_scores(rgb, CANDIDATES)
    np.testing.assert_allclose(np.asarray(moments), np.asarray(direct), rtol=1e-6, atol=1e-6)


def _printed_rgb(rng, shift=1.0):
    """A thin red vertical stripe running `shift` px beside the vertical edges of a printed
    chequer (24 px squares, reflectance 0.07 / 1): (8-bit RGB frame, true column)."""
    h, w = 160, 200
    vv, uu = np.mgrid[0:h, 0:w]
    refl = np.where(((uu // 24) + (vv // 24)) % 2 == 0, 1.0, 0.07)
    u_true = 96.0 + shift  # the chequer's vertical edges lie at multiples of 24 px
    laser = 90.0 * np.exp(-0.5 * ((uu - u_true) / 1.0) ** 2)
    rgb = np.stack([110 * refl + laser * refl, 110 * refl, 110 * refl], -1)
    rgb = rgb + rng.normal(0, 1.5, rgb.shape)
    return np.clip(rgb, 0, 255).round(), u_true


def test_printed_target_divided_by_reflectance():
    from cslx.segmentation.robust import _reflectance_normalised

    rng = np.random.default_rng(12)
    rgb, u_true = _printed_rgb(rng)
    img = jnp.asarray(rgb, jnp.float32)
    mono = img @ jnp.asarray([1.0, -1.0, 0.0])
    norm = _reflectance_normalised(img, mono)
    errs = []
    for m in (mono, norm):
        c, _ = linked_centres(np.asarray(m), sigma=2.5, axis=1, sigma_along=6.0)
        e = np.abs(np.asarray(c.pos) - u_true)
        errs.append(np.nanpercentile(e[10:-10], 90))
    # The reflectance step beside the stripe pulls its centre towards the white squares.
    assert errs[0] > 0.1 and errs[1] < 0.5 * errs[0]
    # A frame without print is left as it is.
    plain = jnp.asarray(np.full((60, 80, 3), 100.0) + rng.normal(0, 2, (60, 80, 3)), jnp.float32)
    pm = plain @ jnp.asarray([1.0, -1.0, 0.0])
    np.testing.assert_array_equal(np.asarray(_reflectance_normalised(plain, pm)), np.asarray(pm))


def test_tilted_stripe_stays_straight_up_to_the_image_border():
    """The smoothing along the stripe mirrors the image at its border, which bends a tilted
    stripe there; the path's border centres come from the fit through the interior."""
    rng = np.random.default_rng(13)
    h, w = 160, 200
    vv, uu = np.mgrid[0:h, 0:w]
    u_true = 90.0 + 0.35 * (vv[:, 0] - 80)
    img = 20.0 + 120.0 * np.exp(-0.5 * ((uu - u_true[:, None]) / 1.3) ** 2)
    img = img + rng.normal(0, 2.0, img.shape)
    c = extract(img, "linked", stripe="v")
    err = np.abs(np.asarray(c.pos) - u_true)
    raw, _ = linked_centres(img, sigma=2.5, axis=1, sigma_along=6.0)
    err_raw = np.abs(np.asarray(raw.pos) - u_true)
    assert np.isfinite(err).all()
    assert err_raw[0] > 1.0  # the mirrored border bends the raw path by > 1 px
    assert err[:4].max() < 0.2 and err[-4:].max() < 0.2


def test_kurtosis_search_ignores_spaces_flat_up_to_rounding():
    # A red stripe beside perfectly constant G and B (float32): a space that cancels R
    # (e.g. −2G + 2B) is flat, and its rounding noise must not outscore the stripe.
    from cslx.segmentation.robust import search_space_unclipped

    rng = np.random.default_rng(3)
    img, v_true = _cross(rng)
    rgb = np.stack([img, np.full_like(img, 40.0), np.full_like(img, 30.0)], -1)
    w = np.asarray(search_space_unclipped(rgb.astype(np.float32), axis=0))
    assert w[0] > 0
    mono = rgb @ w
    rows = np.argmax(mono[:, :100], axis=0)  # left of the vertical stripe
    assert np.all(np.abs(rows - v_true[:100]) <= 1.5)


def test_second_pass_divides_a_reflectance_slope_out(monkeypatch):
    """A smooth reflectance rise beside the stripe (no printed target: the first pass's gate
    stays off) pulls the centre towards the brighter side; the second pass, run on the image
    divided by the reflectance, removes most of that pull."""
    from cslx.segmentation import robust

    rng = np.random.default_rng(14)
    h, w = 100, 160
    vv = np.arange(h)[:, None].astype(float)
    v_true = 50.3 + 0.02 * (np.arange(w) - 80)
    refl = 0.45 + 0.55 / (1 + np.exp(-(vv - v_true[None, :] - 1.0) / 1.2))
    laser = 150.0 * np.exp(-0.5 * ((vv - v_true[None, :]) / 1.3) ** 2)
    rgb = np.stack([refl * (110 + laser), 110 * refl, 110 * refl], -1)
    rgb = np.clip(rgb + rng.normal(0, 1.0, rgb.shape), 0, 255)
    errs = {}
    for divide in (False, True):
        monkeypatch.setattr(robust, "REFINE_REFLECTANCE", divide)
        c = extract(rgb, "linked", space="r-g", stripe="h")
        errs[divide] = np.median(np.abs(np.asarray(c.pos) - v_true)[10:-10])
    assert errs[False] > 0.1
    assert errs[True] < 0.5 * errs[False]


def test_search_mask_adds_near_clipped_pixels(monkeypatch):
    # JPEG leaves a saturated core at 251–255: for the colour search (only) a pixel with a
    # channel at SEARCH_CLIP_LEVEL or above counts as clipped too.
    from cslx.segmentation import search
    from cslx.segmentation.clipped import clipped_mask

    img = np.full((4, 5, 3), 120.0, np.float32)
    img[1, 1] = (255, 200, 190)  # clipped
    img[1, 2] = (251, 240, 230)  # JPEG-broken core pixel
    img[2, 3] = (239, 120, 110)  # a bright flank: kept
    clipped = clipped_mask(img)
    mask = np.asarray(search.search_mask(img, clipped))
    assert mask[1, 1] and mask[1, 2] and not mask[2, 3] and mask.sum() == 2
    monkeypatch.setattr(search, "SEARCH_CLIP_LEVEL", None)
    assert np.array_equal(np.asarray(search.search_mask(img, clipped)), np.asarray(clipped))
