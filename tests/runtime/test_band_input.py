"""Bands cut from the RGB frame first (issue 13) equal the bands of the converted frame."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.runtime.band_input import (
    band_image,
    frame_input,
    frame_stats,
    image_cutter,
    rgb_cutter,
    sheared_band,
)
from cslx.runtime.pipeline import PipelineConfig, _bands, _dome, init_state
from cslx.segmentation.robust import MAX_RUN

W = (1.0, -1.0, 0.0)


def _clipped_frame(seed, h=120, w=96):
    """Random frame with clipped runs of every length (some longer than MAX_RUN) everywhere,
    so that runs cross every band edge and the frame border."""
    rng = np.random.default_rng(seed)
    rgb = rng.integers(0, 200, (h, w, 3), dtype=np.uint8)
    for _ in range(60):
        r, c, n = rng.integers(0, h), rng.integers(0, w), rng.integers(1, MAX_RUN + 8)
        if rng.random() < 0.5:
            rgb[r : r + n, c, rng.integers(0, 3)] = 255
        else:
            rgb[r, c : c + n, rng.integers(0, 3)] = 255
    return jnp.asarray(rgb)


#: The domed fill along both axes (heights 1 / 0.5), every gate on.
DOME_BOTH = (1.0, 0.5, 0.5, 3, 1, 4)


@pytest.mark.parametrize("dome", [(), DOME_BOTH])
@pytest.mark.parametrize("seed", [0, 1])
def test_band_image_equals_band_of_filled_frame(seed, dome):
    rgb = _clipped_frame(seed)
    I_h, I_v = frame_input(rgb, W, jnp.float32, True, dome)
    # the fill changed something, or the test would not test it
    assert not np.array_equal(np.asarray(I_h), np.asarray(I_v))
    cut = jax.jit(band_image, static_argnums=(2, 3, 4, 5, 6, 7))
    for axis, ref, size in ((0, I_h, 16), (1, I_v, 24)):
        n = rgb.shape[axis]
        for start in (0, 1, 7, 30, n // 2, n - size - 1, n - size):
            got = np.asarray(cut(rgb, start, size, axis, W, jnp.float32, True, dome))
            want = np.asarray(jax.lax.dynamic_slice_in_dim(ref, start, size, axis))
            np.testing.assert_array_equal(got, want)
    # without the fill: the colour image's band
    plain = np.asarray(cut(rgb, 5, 16, 0, W, jnp.float32, False))
    np.testing.assert_array_equal(plain, np.asarray(frame_input(rgb, W, jnp.float32, False))[5:21])


#: The tracker's dome (`tracking_config`): down the columns, no test across them.
DOME_TRACKER = (1.0, 0.0, 0.5, 7, 1, 0)


@pytest.mark.parametrize("dome", [(), DOME_TRACKER])
def test_sheared_band_equals_interpolated_rows_of_filled_frame(dome):
    """A band following a leaning stripe (`sheared_band`, `cslx.runtime.band_lean`): column
    u's samples are the filled frame's rows start[u] + r, interpolated between whole rows;
    exact where start[u] is a whole row. Starts at both frame borders, steep both ways."""
    rgb = _clipped_frame(1)
    I_h, I_v = frame_input(rgb, W, jnp.float32, True, dome)
    cut = jax.jit(sheared_band, static_argnums=(2, 3, 4, 5, 6, 7))
    for axis, ref, size in ((0, np.asarray(I_h), 16), (1, np.asarray(I_v).T, 24)):
        n, m = rgb.shape[axis], rgb.shape[1 - axis]
        for c, b in ((0.0, 0.7), (n - size - 1.0, -0.9), (40.3, 0.13), (3.0, 0.0)):
            start = np.clip(c + b * np.arange(m), 0, n - size - 1).astype(np.float32)
            got = np.asarray(cut(rgb, jnp.asarray(start), size, axis, W, jnp.float32, True, dome))
            from_frame = np.asarray(image_cutter((I_h, I_v))(axis, jnp.asarray(start), size))
            got, from_frame = (got, from_frame) if axis == 0 else (got.T, from_frame.T)
            first = np.floor(start).astype(int)
            f = start - first
            rows = np.take_along_axis(ref, first[None] + np.arange(size + 1)[:, None], 0)
            want = (1 - f) * rows[:-1] + f * rows[1:]
            np.testing.assert_allclose(got, want, rtol=0, atol=1e-4)
            np.testing.assert_allclose(from_frame, want, rtol=0, atol=1e-4)
            whole = f == 0
            assert whole.any()
            np.testing.assert_array_equal(got[:, whole], rows[:-1][:, whole])


def test_bands_from_rgb_equal_bands_of_converted_frame():
    """The tracking branch of the pipeline: MED + Steger on bands cut from the RGB frame
    give the centres and filters of the bands of the whole converted frame."""
    rgb = _clipped_frame(3, 240, 320)
    # a bright stripe in each direction so that MED and Steger have something to find
    rgb = np.asarray(rgb).copy()
    rgb[118:123, :, 0] = 250
    rgb[:, 200:205, 0] = 250
    rgb = jnp.asarray(rgb)
    config = PipelineConfig(roi_half_h=16, roi_half_w=24)
    state = init_state(config, (320, 240))
    state = state.__class__(**{**vars(state), "row0": jnp.int32(104), "col0": jnp.int32(180)})
    shape = (240, 320)

    @jax.jit
    def both(rgb, state):
        new = _bands(rgb_cutter(rgb, W, jnp.float32), shape, state, config)
        old = _bands(image_cutter(frame_input(rgb, W, jnp.float32)), shape, state, config)
        return new, old

    new, old = both(rgb, state)
    # the inputs are equal (above); the programs fuse differently: float32 rounding only
    for a, b in zip(jax.tree_util.tree_leaves(new), jax.tree_util.tree_leaves(old), strict=True):
        a, b = np.asarray(a), np.asarray(b)
        if a.dtype.kind == "f":
            np.testing.assert_allclose(a, b, rtol=1e-5, atol=1e-4)
        else:
            np.testing.assert_array_equal(a, b)
    assert np.asarray(new[0].valid).sum() > 200


def test_frame_stats_subsample():
    rgb = _clipped_frame(2)
    full = frame_stats(rgb, jnp.float32, 1)
    assert float(full[0]) == pytest.approx(float(np.mean(np.asarray(rgb, np.float64))), rel=1e-5)
    assert float(full[1]) == pytest.approx(float(np.mean(np.any(np.asarray(rgb) >= 255, -1))))
    sub = frame_stats(rgb, jnp.float32, 4)
    assert float(sub[0]) == pytest.approx(float(full[0]), rel=0.05)


def _stripe_glint_blob():
    """Grey frame (60) with a horizontal red stripe whose R core clips over 12 rows (rows
    25–36) in columns 4–59, a white glint (all channels 255, rows 8–17, columns 28–33) in a
    red halo, and a compact red blob clipped in R only (rows 44–53, columns 10–13) in one."""
    y = np.arange(64)[:, None].astype(float)
    rgb = np.full((64, 64, 3), 60.0)
    rgb[:, 4:60, 0] = 60 + 400 * np.exp(-0.5 * ((y - 30.5) / 5.0) ** 2)
    rgb[6:20, 26:36, 0] = 150
    rgb[8:18, 28:34] = 255
    rgb[42:56, 8:16, 0] = 150
    rgb[44:54, 10:14, 0] = 255
    return jnp.asarray(np.clip(rgb, 0, 255).astype(np.uint8))


#: The gated dome of `PipelineConfig` (issue 12, opt-in): height 1 down the columns, runs
#: longer than 7 px, at most half of them white or without a clipped pixel 6 px to a side.
DOME_GATED = _dome(
    PipelineConfig(
        clip_dome=1.0, clip_dome_axes=1, clip_dome_min_run=7, clip_dome_white=0.5, clip_dome_along=6
    )
)


def test_gated_dome_ridges_a_clipped_stripe_core_but_not_a_glint_or_a_blob():
    """The domed fill (issue 12): a stripe's clipped core gets a ridge at its middle; a
    white glint and a compact clipped blob keep the flat level (no ridge)."""
    rgb = _stripe_glint_blob()
    assert np.array_equal(np.flatnonzero(np.asarray(rgb)[:, 20, 0] == 255), np.arange(25, 37))
    I_h = np.asarray(frame_input(rgb, W, jnp.float32, True, DOME_GATED)[0])
    core = I_h[25:37, 20]
    # a ridge: highest at the run's middle (rows 30 / 31), falling to both ends, curved
    assert np.argmax(core) in (5, 6)
    assert np.all(np.diff(core[:6]) > 0) and np.all(np.diff(core[6:]) < 0)
    assert core[5] - core[0] > 0.2 * core[0]
    # the glint and the blob: one flat level, as the flat fill writes
    flat = np.asarray(frame_input(rgb, W, jnp.float32, True, ())[0])
    for rows, col in ((slice(8, 18), 30), (slice(44, 54), 11)):
        np.testing.assert_array_equal(I_h[rows, col], flat[rows, col])
        assert np.ptp(I_h[rows, col]) == 0
    # the flat fill writes one level over the core: no ridge there
    assert np.ptp(flat[25:37, 20]) == 0
    # the colour gate alone keeps the glint flat; the blob (red only) needs the geometry gate
    colour = DOME_GATED[:5] + (0,)
    I_c = np.asarray(frame_input(rgb, W, jnp.float32, True, colour)[0])
    assert np.ptp(I_c[8:18, 30]) == 0 and np.ptp(I_c[44:54, 11]) > 0


def test_tracker_default_domes_a_clipped_stripe_core_and_keeps_a_glint_flat():
    """The tracker's pipeline (`tracking_config`) uses the gated dome: the clipped core gets
    a ridge at its middle, the white glint keeps the flat fill's level."""
    from cslx.runtime.tracker import tracking_config

    rgb = _stripe_glint_blob()
    I_h = np.asarray(frame_input(rgb, W, jnp.float32, True, _dome(tracking_config()))[0])
    flat = np.asarray(frame_input(rgb, W, jnp.float32, True, ())[0])
    core = I_h[25:37, 20]
    assert np.argmax(core) in (5, 6) and core[5] - core[0] > 0.2 * core[0]
    np.testing.assert_array_equal(I_h[8:18, 30], flat[8:18, 30])


def test_centre_runs_length_and_white():
    """`centre_runs` (issue 12): the clipped run through a centre's pixel down its column,
    and whether it holds a white (non-laser channel) pixel; 0 off a run or for no centre."""
    from cslx.segmentation.clipped import centre_runs

    rgb = _stripe_glint_blob()
    W_ = rgb.shape[1]
    pos = np.full(W_, 3.0)  # rows 3: unclipped everywhere
    valid = np.ones(W_, bool)
    pos[20], pos[30], pos[11], pos[5] = 30.4, 12.0, 49.0, 30.0
    valid[5] = False
    length, white = centre_runs(rgb, jnp.asarray(pos), jnp.asarray(valid), W, axis=0)
    length, white = np.asarray(length), np.asarray(white)
    expect_core = int(np.sum(np.asarray(rgb)[:, 20].max(-1) >= 254))
    assert length[20] == expect_core == 12 and not white[20]  # the stripe's red core
    assert length[30] == 10 and white[30]  # the white glint, rows 8–17
    assert length[11] == 10 and not white[11]  # the red blob, rows 44–53
    assert length[5] == 0 and length[0] == 0  # no centre / an unclipped pixel
    # the vertical stripe's axis: rows searched along the columns, the same as transposed
    lt, wt = centre_runs(
        jnp.transpose(rgb, (1, 0, 2)), jnp.asarray(pos), jnp.asarray(valid), W, axis=1
    )
    np.testing.assert_array_equal(np.asarray(lt), length)
    np.testing.assert_array_equal(np.asarray(wt), white)


def _stripe_over_shadow_edge(h=40, w=40, row=20.0):
    """A red stripe along the rows (row ``row``, σ 1.5 px, its core clipped in R) over grey
    plate: columns < w/2 in uniform shade (grey 30), columns ≥ w/2 across a shadow edge that
    runs along the stripe (grey 30 above ``row``, 200 below; rendered shadow, issue 12)."""
    r = np.arange(h, dtype=float)[:, None]
    laser = 400.0 * np.exp(-0.5 * ((r - row) / 1.5) ** 2) * np.ones((1, w))
    grey = np.full((h, w), 30.0)
    grey[int(row) + 1 :, w // 2 :] = 200.0
    rgb = np.stack([grey + laser, grey + 0.07 * laser, grey + 0.04 * laser], -1)
    return np.clip(np.round(rgb), 0, 255).astype(np.uint8)


def test_background_step_sees_a_shadow_edge_across_the_stripe():
    """`background_step` (issue 12): the subtracted channel (G of R − G) changes across the
    stripe by ≈ 170 grey levels against a clipped laser channel (255) where the shadow edge
    runs along it, and by nothing on uniform shade; 0 for a missing centre."""
    from cslx.segmentation.clipped import background_step

    rgb = _stripe_over_shadow_edge()
    pos = np.full(rgb.shape[1], 20.3)
    valid = np.ones(rgb.shape[1], bool)
    valid[3] = False
    step = np.asarray(background_step(jnp.asarray(rgb), jnp.asarray(pos), jnp.asarray(valid), W, 6))
    assert np.all(step[:20] < 0.05)
    assert np.all(step[20:] > 0.5), step[20:]
    assert step[3] == 0.0


def test_edge_weight_drops_centres_on_a_shadow_edge_from_the_cap_fit():
    """`PipelineConfig.edge_weight` (issue 12): the horizontal stripe's centres where the
    background steps across the stripe get that weight in the bead's cap fit, the others 1;
    with the weight 1 (and no clip weight) there are no weights at all."""
    from types import SimpleNamespace

    from cslx.runtime.pipeline import _clip_weights

    rgb = jnp.asarray(_stripe_over_shadow_edge())
    ch = SimpleNamespace(pos=jnp.full(40, 20.3), valid=jnp.ones(40, bool))
    cfg = PipelineConfig(use_med=False, edge_weight=0.0, edge_weight_ratio=0.4)
    w = np.asarray(_clip_weights(rgb, ch, cfg, jnp.float32))
    np.testing.assert_array_equal(w, np.r_[np.ones(20), np.zeros(20)])
    assert _clip_weights(rgb, ch, PipelineConfig(use_med=False), jnp.float32) is None


def test_tracking_config_drops_centres_on_a_shadow_edge():
    """The tracker's pipeline (`cslx.runtime.tracker.tracking_config`) weights the centres on
    the shadow edge 0 in the bead's fit and leaves those on uniform shade at 1."""
    from types import SimpleNamespace

    from cslx.runtime.pipeline import _clip_weights
    from cslx.runtime.tracker import tracking_config

    rgb = jnp.asarray(_stripe_over_shadow_edge())
    ch = SimpleNamespace(pos=jnp.full(40, 20.3), valid=jnp.ones(40, bool))
    w = np.asarray(_clip_weights(rgb, ch, tracking_config(), jnp.float32))
    np.testing.assert_array_equal(w, np.r_[np.ones(20), np.zeros(20)])
