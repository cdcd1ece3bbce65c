"""The whole per-frame pipeline in one compiled function: RGB frame → stripes → 3-D → weld.

One frame (docs/architecture.md):

1. colour space, eq. (8): I = w_r R + w_g G + w_b B (static weights, R − G by default);
2. MED, eqs. (18)–(24): one FIR filter down the columns (horizontal stripe) and one along
   the rows (vertical stripe), each warm-started from the previous frame's filter held in
   `PipelineState` (docs/corrections.md, 5), delay-compensated (correction 6);
3. Steger's detector on each MED output: one sub-pixel centre per column / per row;
4. triangulation (correction 3 of eq. (27)) on plane 0 / plane 1 into the robot frame;
5. weld features (`cslx.runtime.weld.weld_features`): the followed bead on the horizontal stripe,
   a crossing bead (T-junction) on the vertical stripe.

Tracking mode (region of interest). In video the stripes barely move between frames, so
after a frame where both stripes were found the next frame processes only a band of
``2·roi_half_h`` rows around the horizontal stripe (all columns) and a band of
``2·roi_half_w`` columns around the vertical stripe (all rows). The band sizes are static,
their offsets dynamic (`lax.dynamic_slice`), so one compiled program serves every frame;
`lax.cond` picks the band branch or the full-frame branch (on the CPU only the chosen branch
runs). The MED filters of the bands are shorter (``L_roi``, a band is a short segment) and
kept apart from the full-frame filters. A stripe that leaves its band, or too few centres,
switches the next frame back to a frame without tracking state. A stripe that leans more
than its straight band holds (a rolled projector) gets a band sheared along its fitted line
(`cslx.runtime.band_lean`; the rows interpolated, the centres shifted back per column).
Such a frame (the first one too) takes its bands from a cheap first pass (the brightest
sample of every column / row, `_first_pass`) and runs MED from the band filters to
convergence there; only when the stripes do not fit the bands does it run MED on the full
frame. Centres outside the band are reported as not found; inside it they agree with
full-frame processing (tests/runtime/test_pipeline.py). The bands are cut out of the uint8
RGB frame before the colour sum and the clipped-core fill (``band_first``,
`cslx.runtime.band_input`; the same values as the bands of the converted frame), so a
tracking frame never converts the whole frame.

Everything is pure JAX on one frame and jit-compiled at `process_frame`;
`cslx.runtime.batch.process_batch` runs it over a stack of frames (under vmap `lax.cond`
evaluates both branches: archives should use the full frame, ``roi=False``).
"""

from __future__ import annotations

import dataclasses
import functools
from typing import NamedTuple

import equinox as eqx
import jax
import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Bool, Float, Int, UInt8

from ..reductions import first_argmax
from ..segmentation.clipped import background_step, centre_runs
from ..segmentation.med import initial_filter, med, med_apply, med_output
from ..segmentation.med_bands import band_snr_scale
from ..segmentation.steger import Centres, steger_centres
from ..sensor import Sensor, triangulate
from .band_input import band_image, colour_sum, frame_input, frame_stats, image_cutter, rgb_cutter
from .band_lean import band_cut, lean_allowed, next_bands
from .pipeline_config import PipelineConfig
from .small_ops import window_nanmedian
from .weld import WeldFeature, weld_features

__all__ = [
    "FrameResult",
    "PipelineConfig",
    "PipelineState",
    "frame_summary",
    "init_state",
    "process_frame",
    "SUMMARY_FIELDS",
    "stripe_points",
    "clean_profile",
    "colour_sum",
]


class PipelineState(eqx.Module):
    """What one frame hands to the next: MED filters (warm start) and the tracking bands.

    filter_h / filter_v: full-frame filters (L_h,), (L_v,); roi_filter_h / roi_filter_v:
    band filters (L_roi,). row0: first row of the horizontal stripe's band; col0: first
    column of the vertical stripe's band; lean_h / lean_v: (s₀, b) of a band that follows a
    leaning stripe, (0, 0) for the straight band at row0 / col0 (`cslx.runtime.band_lean`);
    tracking: process the bands (True) or the full frame (False) next. turn: which band's
    filter steps on the next tracking frame with ``roi_med_alternate`` (True: h; flipped
    on every band frame).
    """

    filter_h: Float[Array, " Lh"]
    filter_v: Float[Array, " Lv"]
    roi_filter_h: Float[Array, " Lr"]
    roi_filter_v: Float[Array, " Lr"]
    row0: Int[Array, ""]
    col0: Int[Array, ""]
    tracking: Bool[Array, ""]
    lean_h: Float[Array, " 2"]
    lean_v: Float[Array, " 2"]
    turn: Bool[Array, ""]


class FrameResult(NamedTuple):
    """Everything the pipeline found in one frame (leading batch axis under vmap).

    centres_h: per-column centres of the horizontal stripe (W,); centres_v: per-row centres
    of the vertical stripe (H,) (OpenCV pixels; NaN where not valid). points_h (W, 3),
    points_v (H, 3): robot-frame points, mm, after `clean_profile` (outliers dropped,
    lightly smoothed; NaN where not valid or dropped). feature_h / feature_v:
    the beads (`cslx.runtime.weld.WeldFeature`); junction: the T-junction flag. med_steps: (2,)
    fixed-point steps (h, v); kurtosis: (2,) excess kurtosis of the MED outputs. used_roi:
    only the bands were processed (tracking mode, or the bands of the first pass on a frame
    without tracking state). brightness: mean grey level of the frame
    (0..255); saturated: fraction of pixels with a channel at 255.
    """

    centres_h: Centres
    centres_v: Centres
    points_h: Float[Array, "w 3"]
    points_v: Float[Array, "h 3"]
    feature_h: WeldFeature
    feature_v: WeldFeature
    junction: Bool[Array, ""]
    med_steps: Int[Array, " 2"]
    kurtosis: Float[Array, " 2"]
    used_roi: Bool[Array, ""]
    brightness: Float[Array, ""]
    saturated: Float[Array, ""]


def init_state(
    config: PipelineConfig, image_size: tuple[int, int], dtype=jnp.float32
) -> PipelineState:
    """Cold state: full-frame filters from ``config.start``, flat band filters (W = 1/√L,
    Table 2), and full-frame processing (or the first pass's bands) first.

    Args:
        config: the pipeline settings.
        image_size: (W, H) in pixels, as `Camera.image_size`.
        dtype: float dtype of the filters (float32 is the speed path).
    """
    width, height = image_size
    L_h, L_v = config.lengths(height, width)
    return PipelineState(
        filter_h=initial_filter(config.start, L_h, dtype),
        filter_v=initial_filter(config.start, L_v, dtype),
        roi_filter_h=initial_filter("flat", config.L_roi, dtype),
        roi_filter_v=initial_filter("flat", config.L_roi, dtype),
        row0=jnp.zeros((), jnp.int32),
        col0=jnp.zeros((), jnp.int32),
        tracking=jnp.zeros((), bool),
        lean_h=jnp.zeros(2, dtype),
        lean_v=jnp.zeros(2, dtype),
        turn=jnp.zeros((), bool),
    )


def _stripe(
    I,
    W0,
    axis,
    L,
    config: PipelineConfig,
    max_steps,
    use_med,
    symmetric=False,
    size=0,
    stride=1,
    lag=False,
    refresh=None,
):
    """MED (warm start W0) then Steger on one image or band: (centres, filter, steps, kurtosis).

    ``stride`` > 1: the filter is found on every stride-th segment and applied to all.
    ``lag``: the output of W0 and one step from it for the next frame (`med`'s ``lag``).
    """
    if use_med:
        sub = I if stride == 1 else (I[:, ::stride] if axis == 0 else I[::stride])
        r = med(
            sub,
            axis=axis,
            L=L,
            init=W0,
            tol=config.tol,
            max_steps=max_steps,
            delay="centre" if symmetric else config.med_delay,
            ridge_sigma=config.sigma,
            symmetric=symmetric,
            lag=lag,
            lag_stride=config.roi_lag_stride if lag else 1,
            refresh=refresh,
        )
        finite = jnp.isfinite(r.kurtosis)  # NaN where ``refresh`` skipped the step
        finite = finite if refresh is None else finite | (r.steps == 0)
        ok = jnp.all(jnp.isfinite(r.filter)) & finite
        # A black or clipped frame has no variance: keep the old filter, never a NaN one.
        W = jnp.where(ok, r.filter, W0)

        def out():
            if stride == 1:
                return r.output
            if symmetric:
                return med_apply(I, r.filter, axis=axis, delay="centre")[0]
            # the delay measured on the strided segments (`med_output`: one FFT pass pair)
            return med_output(I, r.filter, r.delay, axis=axis)

        B = lax.cond(ok, out, lambda: I)  # not a select (band_input's notes)
        steps, kurt = r.steps.astype(jnp.int32), jnp.where(ok, r.kurtosis, jnp.nan)
    else:
        W, B, steps, kurt = W0, I, jnp.zeros((), jnp.int32), jnp.asarray(jnp.nan, I.dtype)
    # In a band, Steger's noise floor is scaled to the frame's (`band_snr_scale`).
    snr = config.snr * (band_snr_scale(I.shape[axis], size) if size else 1.0)
    c = steger_centres(B, sigma=config.sigma, axis=axis, threshold=config.threshold, snr=snr)
    return c, W, steps, kurt


def _shift(c: Centres, offset) -> Centres:
    return Centres(c.pos + offset.astype(c.pos.dtype), c.valid, c.strength)


def _full(I, state: PipelineState, config: PipelineConfig):
    I_h, I_v = I if isinstance(I, tuple) else (I, I)
    height, width = I_h.shape
    L_h, L_v = config.lengths(height, width)
    steps = config.max_steps
    k = config.med_stride
    ch, Wh, sh, kh = _stripe(I_h, state.filter_h, 0, L_h, config, steps, config.use_med, stride=k)
    cv, Wv, sv, kv = _stripe(I_v, state.filter_v, 1, L_v, config, steps, config.use_med, stride=k)
    new = eqx.tree_at(lambda s: (s.filter_h, s.filter_v), state, (Wh, Wv))
    return ch, cv, jnp.stack([sh, sv]), jnp.stack([kh, kv]), new, jnp.zeros((), bool)


def _bands(cut, shape, state: PipelineState, config: PipelineConfig, max_steps=None):
    # tracking frames: ``roi_max_steps`` (or the lagged step); a first-pass frame converges
    lag = config.roi_med_lag and max_steps is None
    max_steps = config.roi_max_steps if max_steps is None else max_steps
    height, width = shape
    lean = lean_allowed(config)  # a sheared band along a leaning stripe (`band_lean`)
    band_h, off_h = band_cut(cut, 0, state.row0, state.lean_h, 2 * config.roi_half_h, shape, lean)
    band_v, off_v = band_cut(cut, 1, state.col0, state.lean_v, 2 * config.roi_half_w, shape, lean)
    med_on, sym = config.use_med and config.roi_med, config.roi_symmetric
    L = config.L_roi
    turn = state.turn  # with roi_med_alternate: h steps on a True turn, v on a False one
    alt = lag and med_on and config.roi_med_alternate
    ch, Wh, sh, kh = _stripe(
        band_h, state.roi_filter_h, 0, L, config, max_steps, med_on, sym, height, lag=lag,
        refresh=turn if alt else None,
    )  # fmt: skip
    cv, Wv, sv, kv = _stripe(
        band_v, state.roi_filter_v, 1, L, config, max_steps, med_on, sym, width, lag=lag,
        refresh=~turn if alt else None,
    )  # fmt: skip
    new = eqx.tree_at(lambda s: (s.roi_filter_h, s.roi_filter_v, s.turn), state, (Wh, Wv, ~turn))
    return (
        _shift(ch, off_h),
        _shift(cv, off_v),
        jnp.stack([sh, sv]),
        jnp.stack([kh, kv]),
        new,
        jnp.ones((), bool),
    )


def _first_pass(cols, rows, shape, state: PipelineState, config: PipelineConfig):
    """Bands from a cheap first pass on a frame without tracking state: (state, fits).

    The brightest sample of every column of ``cols`` (row of ``rows``: the monochrome
    image, or every k-th column / row of it) is a rough stripe position; the bands are
    centred on their medians. They are used when nearly all of those positions fall inside
    (the `band_lean.next_bands` rule: 98 %, away from the band edges); stray maxima (the other
    stripe, a glint) are the few columns left out. Otherwise the frame goes through
    full-frame MED.
    """
    height, width = shape
    peaks_h, peaks_v = first_argmax(cols, 0)[0], first_argmax(rows, 1)[0]
    hh, hw, m = config.roi_half_h, config.roi_half_w, config.roi_margin

    def band(peaks, half, size):
        centre = jnp.median(peaks.astype(jnp.float32))
        start = jnp.clip(jnp.round(centre).astype(jnp.int32) - half, 0, size - 2 * half)
        lo = jnp.where(start == 0, -1, start + m)
        hi = jnp.where(start == size - 2 * half, size, start + 2 * half - 1 - m)
        inside = jnp.mean((peaks >= lo) & (peaks <= hi))
        return start, inside >= config.first_pass_fraction

    row0, ok_h = band(peaks_h, hh, height)
    col0, ok_v = band(peaks_v, hw, width)
    new = eqx.tree_at(lambda s: (s.row0, s.col0), state, (row0, col0))
    return new, ok_h & ok_v


def _cold(I, state: PipelineState, config: PipelineConfig):
    """A frame without tracking: the bands of `_first_pass` if the stripes fit, else full."""
    if not config.first_pass:
        return _full(I, state, config)
    I0 = I[0] if isinstance(I, tuple) else I
    banded, fits = _first_pass(I0, I0, I0.shape, state, config)
    return lax.cond(
        fits,
        lambda: _bands(image_cutter(I), I0.shape, banded, config, config.max_steps),
        lambda: _full(I, state, config),
    )


def _cold_rgb(rgb, state: PipelineState, config: PipelineConfig, dtype):
    """`_cold` with ``band_first``: the first pass on every k-th column (row), each filled
    along its own search axis; the whole frame is converted only when the bands fail."""
    shape = rgb.shape[:2]
    k, w, fill = config.first_pass_stride, config.weights, config.fill_clipped
    dome = _dome(config)
    full = lambda: _full(frame_input(rgb, w, dtype, fill, dome), state, config)  # noqa: E731
    if not config.first_pass:
        return full()
    zero = jnp.zeros((), jnp.int32)
    cols = band_image(rgb[:, ::k], zero, shape[0], 0, w, dtype, fill, dome)
    rows = band_image(rgb[::k], zero, shape[1], 1, w, dtype, fill, dome)
    banded, fits = _first_pass(cols, rows, shape, state, config)
    cut = rgb_cutter(rgb, config.weights, dtype, config.fill_clipped, dome)
    return lax.cond(fits, lambda: _bands(cut, shape, banded, config, config.max_steps), full)


def stripe_points(sensor: Sensor, c: Centres, axis: int, plane: int, dtype):
    """Triangulate valid centres into the robot frame; NaN rows where not valid."""
    n = c.pos.shape[0]
    index = jnp.arange(n, dtype=dtype)
    # Invalid centres get a harmless pixel so the undistortion fixed point converges fast.
    pos = jnp.where(c.valid, c.pos, 0.5 * n).astype(dtype)
    uv = jnp.stack([index, pos] if axis == 0 else [pos, index], axis=-1)
    X = triangulate(sensor, uv, plane, robot_frame=True)
    return jnp.where(c.valid[:, None], X, jnp.nan)


def _windows(x: Array, k: int, fill) -> Array:
    """(N, 2k+1) stack of x shifted by −k..k along the first axis (``fill`` past the ends)."""
    pad = [(k, k)] + [(0, 0)] * (x.ndim - 1)
    xp = jnp.pad(x, pad, constant_values=fill)
    n = x.shape[0]
    return jnp.stack([lax.slice_in_dim(xp, j, j + n) for j in range(2 * k + 1)], axis=1)


def clean_profile(P: Float[Array, "n 3"], valid: Bool[Array, " n"], config: PipelineConfig):
    """Drop gross 3-D outliers and lightly smooth a stripe profile before the weld features.

    A centre picked on the wrong ridge (where the stripes cross, a glint) triangulates tens
    or hundreds of mm off the wall and splits the bead's run of high points; a point is
    dropped when its z_r is more than ``outlier_mm`` from the median z_r of its
    2·``median_half``+1 neighbours. The rest is averaged over 2·``smooth_half``+1 valid
    neighbours (≈ 1–2 mm of wall, 10× narrower than a bead; the points stay on the laser
    plane), which lowers the speckle noise of the profile by ≈ √(2·smooth_half+1).
    """
    z = jnp.where(valid, P[:, 2], jnp.nan)
    med = window_nanmedian(z, config.median_half)  # = nanmedian of the windows, no sort
    keep = valid & (jnp.abs(z - med) <= config.outlier_mm)
    if config.smooth_half > 0:
        w = _windows(keep.astype(P.dtype), config.smooth_half, 0.0)
        X = _windows(jnp.where(keep[:, None], P, 0.0), config.smooth_half, 0.0)
        count = jnp.sum(w, axis=1)
        P = jnp.sum(X, axis=1) / jnp.maximum(count, 1.0)[:, None]
    return jnp.where(keep[:, None], P, jnp.nan), keep


def _frame_config(config: PipelineConfig, height: int, width: int) -> PipelineConfig:
    """`config` with Steger's σ scaled by min(H, W) / 480 above 480 px (see `sigma`)."""
    factor = min(height, width) / 480
    return dataclasses.replace(config, sigma=config.sigma * factor) if factor > 1 else config


def _dome(config: PipelineConfig) -> tuple:
    """The clipped-core fill's dome (`cslx.runtime.band_input._fill`): () for the flat fill."""
    d, axes = config.clip_dome, config.clip_dome_axes
    if d <= 0:
        return ()
    heights = (d if axes & 1 else 0.0, d if axes & 2 else 0.0)
    return (
        *heights,
        config.clip_dome_white,
        config.clip_dome_min_run,
        config.clip_dome_colour,
        config.clip_dome_along,
    )


def _clip_weights(rgb, ch: Centres, config: PipelineConfig, dtype):
    """Weights of the horizontal stripe's points in its bead's cap fit (None: all 1).

    ``config.clip_weight`` for a centre on a clipped run longer than
    ``config.clip_weight_run`` px down its column, or on a clipped run holding a white pixel
    (`cslx.segmentation.clipped.centre_runs`): there the stripe's light was not measured and
    the centre lies where the clipped-core fill put the ridge (`PipelineConfig`)."""
    w = None
    if config.clip_weight != 1.0 and config.fill_clipped:
        length, white = centre_runs(rgb, ch.pos, ch.valid, config.weights, axis=0)
        odd = (length > config.clip_weight_run) | (white & (length > 0))
        w = jnp.where(odd, config.clip_weight, 1.0).astype(dtype)
    if config.edge_weight != 1.0:
        # a shadow edge or glint across the stripe (`PipelineConfig.edge_weight`)
        step = background_step(rgb, ch.pos, ch.valid, config.weights, config.edge_weight_gap)
        ratio, ramp = config.edge_weight_ratio, config.edge_weight_ramp
        if 0 < ramp < ratio:  # linear from 1 at the ramp's start to edge_weight at the ratio
            u = jnp.clip((ratio - step) / (ratio - ramp), 0.0, 1.0)
            e = config.edge_weight + (1.0 - config.edge_weight) * u
        else:
            e = jnp.where(step > ratio, config.edge_weight, 1.0)
        e = e.astype(dtype)
        w = e if w is None else w * e
    return w


def _process(sensor, config: PipelineConfig, rgb, state: PipelineState, roi: bool):
    height, width = rgb.shape[:2]
    config = _frame_config(config, height, width)
    dtype = state.filter_h.dtype
    dome = _dome(config)
    if roi and config.roi_enabled(height, width) and config.band_first:
        cut = rgb_cutter(rgb, config.weights, dtype, config.fill_clipped, dome)
        ch, cv, steps, kurt, new, used_roi = lax.cond(
            state.tracking,
            lambda: _bands(cut, (height, width), state, config),
            lambda: _cold_rgb(rgb, state, config, dtype),
        )
    elif roi and config.roi_enabled(height, width):
        I = frame_input(rgb, config.weights, dtype, config.fill_clipped, dome)
        ch, cv, steps, kurt, new, used_roi = lax.cond(
            state.tracking,
            lambda: _bands(image_cutter(I), (height, width), state, config),
            lambda: _cold(I, state, config),
        )
    else:
        I = frame_input(rgb, config.weights, dtype, config.fill_clipped, dome)
        ch, cv, steps, kurt, new, used_roi = _full(I, state, config)
    new = next_bands(ch, cv, new, config, (height, width))
    Ph, keep_h = clean_profile(stripe_points(sensor, ch, 0, 0, dtype), ch.valid, config)
    Pv, keep_v = clean_profile(stripe_points(sensor, cv, 1, 1, dtype), cv.valid, config)
    fh, fv, junction = weld_features(
        Ph, keep_h, Pv, keep_v, config.weld, _clip_weights(rgb, ch, config, dtype)
    )
    brightness, saturated = frame_stats(rgb, dtype, config.stats_stride)
    result = FrameResult(
        centres_h=ch,
        centres_v=cv,
        points_h=Ph,
        points_v=Pv,
        feature_h=fh,
        feature_v=fv,
        junction=junction,
        med_steps=steps,
        kurtosis=kurt.astype(dtype),
        used_roi=used_roi,
        brightness=brightness,
        saturated=saturated,
    )
    return result, new


def _check_frame(sensor: Sensor, rgb) -> None:
    width, height = sensor.camera.image_size
    if rgb.ndim != 3 or rgb.shape[-1] != 3:
        raise ValueError(f"expected an RGB frame of shape (H, W, 3), got shape {rgb.shape}")
    if rgb.shape[:2] != (height, width):
        raise ValueError(
            f"frame is {rgb.shape[1]}×{rgb.shape[0]} px but the calibration is {width}×{height}"
        )
    if rgb.dtype != jnp.uint8:
        raise ValueError(f"expected a uint8 frame, got dtype {rgb.dtype}")


@functools.partial(jax.jit, static_argnames=("roi",))
def _process_frame(sensor, config, rgb, state, roi):
    return _process(sensor, config, rgb, state, roi)


def process_frame(
    sensor: Sensor,
    config: PipelineConfig,
    rgb: UInt8[Array, "h w 3"],
    state: PipelineState,
    *,
    roi: bool = True,
) -> tuple[FrameResult, PipelineState]:
    """Run the whole pipeline on one RGB frame (module docstring), jit-compiled.

    Args:
        sensor: the calibrated sensor (its image size must match the frame).
        config: `PipelineConfig` (static: a new config compiles a new program).
        rgb: (H, W, 3) uint8 RGB frame.
        state: `PipelineState` from `init_state` or the previous frame.
        roi: allow tracking mode (bands around the last stripes); False always processes the
            full frame (still warm-starting MED from `state`).

    Returns:
        (`FrameResult`, the state for the next frame).
    """
    if not isinstance(rgb, jax.Array):  # jnp.asarray of an Array: ≈ 25 µs a frame (issue 13)
        rgb = jnp.asarray(rgb)
    _check_frame(sensor, rgb)
    program = _bound(sensor, config, roi)
    if program is None:
        return _process_frame(sensor, config, rgb, state, roi)
    return program(rgb, state)


#: (id(sensor), config, roi) → (the sensor, its jitted program); the program holds the
#: sensor, so an id cannot be reused while its entry exists. None → the last call's.
_BOUND: dict = {}
_MAX_BOUND = 8


def _bound(sensor, config, roi: bool):
    """`process_frame`'s program with this sensor object and config value compiled in.

    The tracker's program closes over its calibration and settings
    (`cslx.runtime.step_program`); the generic jit flattens the sensor and config pytrees
    every call and treats their values as run-time arguments. Bound the same way, a tracking
    frame took 2.92 → 2.74 ms (300 interleaved calls on the quiet 2-core CPU, issue 13;
    float32 outputs within 1e-3 of the generic program's). None (the generic program) for a
    traced sensor or config (`jax.grad`, `vmap` through them) or an unhashable config; the
    `_MAX_BOUND` most recent programs are kept.
    """
    last = _BOUND.get(None)  # the same objects as the previous frame: no config hash
    if last is not None and last[0] is sensor and last[1] is config and last[2] == roi:
        return last[3]
    try:
        key = (id(sensor), config, bool(roi))
        hit = _BOUND.get(key)
    except TypeError:  # an unhashable config (array-valued settings)
        return None
    if hit is not None and hit[0] is sensor:
        _BOUND[None] = (sensor, config, roi, hit[1])
        return hit[1]
    if any(isinstance(x, jax.core.Tracer) for x in jax.tree_util.tree_leaves((sensor, config))):
        return None
    while len(_BOUND) > _MAX_BOUND:  # the None entry is the last call's
        del _BOUND[next(k for k in _BOUND if k is not None)]
    program = jax.jit(lambda rgb, state: _process(sensor, config, rgb, state, roi))
    _BOUND[key] = (sensor, program)
    _BOUND[None] = (sensor, config, roi, program)
    return program


#: Names of the entries of `frame_summary`, in order.
SUMMARY_FIELDS = (
    "h_found",
    "h_x_mm",
    "h_y_mm",
    "h_z_mm",
    "h_width_mm",
    "h_height_mm",
    "h_confidence",
    "v_found",
    "v_x_mm",
    "v_confidence",
    "junction",
    "med_steps_h",
    "med_steps_v",
    "used_roi",
    "n_valid_h",
    "n_valid_v",
    "brightness",
    "saturated",
)


def frame_summary(result: FrameResult) -> Float[Array, " k"]:
    """The few numbers a tracker needs from a frame, as one small vector (`SUMMARY_FIELDS`).

    One device→host transfer of this vector per frame is all the tracker's I/O.
    """
    fh, fv = result.feature_h, result.feature_v
    dtype = fh.confidence.dtype
    vals = [
        fh.found,
        fh.centre[0],
        fh.centre[1],
        fh.centre[2],
        fh.width,
        fh.height,
        fh.confidence,
        fv.found,
        fv.position,
        fv.confidence,
        result.junction,
        result.med_steps[0],
        result.med_steps[1],
        result.used_roi,
        jnp.sum(result.centres_h.valid),
        jnp.sum(result.centres_v.valid),
        result.brightness,
        result.saturated,
    ]
    return jnp.stack([jnp.asarray(v).astype(dtype) for v in vals])
