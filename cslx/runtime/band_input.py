"""The pipeline's monochrome input, cut from the RGB frame where it is needed (issue 13).

Tracking mode processes a band of rows around the horizontal stripe and a band of columns
around the vertical one. Building the whole frame's colour image, its clipped mask and the
two `fill_clipped` images (one per stripe axis) cost more than the bands' MED and
detection together (whole frame 10–12 ms at load 5 on the 2-core CPU; a tracking frame
took 53.8 ms that way and 35.8 ms band-first in the same run of experiments/bench_speed.py),
so the bands are cut from the uint8 RGB frame first and only they are converted
(`band_image`).

Equality with the full-frame input. `fill_clipped` fills a clipped run of at most
``max_run`` samples along the search axis from its two unclipped flanks, and leaves runs
that touch the image border or are longer. A band cut with ``max_run + 1`` samples of
context on both sides (clamped at the frame border) contains every run that reaches into
the band together with its flanks, and a run that touches the context's edge is longer than
``max_run``, so it is left unfilled in the frame too: the band of the filled frame equals the
filled band exactly (tests/runtime/test_pipeline.py).

Where a tracking frame's time goes (issue 13; one process per line, calls interleaved,
medians, video seed 1, load 4.4–7.2 on the 2-core CPU): the one jitted call costs
14.4–15.5 ms, its parts jitted alone ≈ 13.3 ms: band cut with the clipped-run fill h 2.0 /
v 2.7 ms (0.09 / 0.19 ms without the fill; every frame of the sunny video has ≈ 5 000
clipped pixels, so the fill's `lax.cond` runs it every time), MED (2 steps) + Steger
h 2.1 / v 2.6 ms, triangulation and profile cleaning 0.9 ms, weld features 2.7 ms (the
junction's pairwise search 1.7 of them), frame statistics 0.24 ms. There is no hidden
per-call cost: the compiled program has one conditional on ``tracking`` whose operands (the
uint8 frame, the filters) are passed without copies, the tracking loop compiles once
(tests/runtime/test_pipeline.py), and the host side (`jnp.asarray` of a NumPy frame, the
shape checks) adds ≈ 1 ms. Fills with equal outputs tried and dropped, none faster at load 6:
a bounded `reduce_window` search, Hillis–Steele scans with gathers or with carried flank
values, 24 shifted selects per side. Kept: `fill_clipped` as one `lax.scan` along its axis
(band of rows 1.56 → 0.43 ms alone, band of columns 2.1 → 0.99 ms) and the junction's apex
arg-max as two reductions (1.67 → 0.96 ms); together the tracking call went 14.64 →
12.78 ms (200 interleaved frames, load 3.6–3.8, identical outputs).

Two more reads of a band, found in a per-kernel profile of the tracking program (issue 13;
`jax.profiler`, each kernel's 10th-percentile duration × its calls): the clipped mask as a
maximum over the length-3 channel axis went to a reduction kernel of ≈ 0.2 ms per band, and
the pipeline's ``jnp.where(ok, MED output, band)`` (``ok`` a scalar) was fused into
Steger's reflect padding, which then read the band through the cut's transpose in four
padding kernels of ≈ 0.1 ms. Now `clipped_mask` takes the maximum channel by channel and
the pipeline chooses with `lax.cond`: band cuts h 0.93 → 0.83 ms, v 1.24 → 1.04 ms (150
interleaved calls, load 7.5–8.7); cut + MED + Steger of both bands 6.70 → 5.83 ms (300,
load 8.3–8.5); the tracking call 10.20 → 9.37 ms (300 interleaved frames,
`experiments.ab_tracking`, load 8.7–10.9); identical outputs.

The cut as its own buffer (issue 13). XLA fused the band's `lax.dynamic_slice` of the frame
into each of its consumers (the colour sum, the clipped mask), and an elementwise kernel
reading through a dynamic slice ran ≈ 4× slower than through a static one (the colour sum
and mask of the 114×640 band of rows 0.21 against 0.05 ms, of both bands 0.54 against
0.21 ms; 400 interleaved calls, load 4–5). `band_image` now cuts the uint8 band in a loop
of one trip (`cslx.runtime.small_ops.one_function`), whose output is a plain buffer the
consumers read: both bands' colour sum and mask 0.49 → 0.24 ms, and the tracking frame
3.80 → 3.11 ms and 3.26 → 2.98 ms median (`experiments.ab_tracking --rev main`, 300 and
400 interleaved frames, load 4.3–5.1); identical outputs. The band of columns' transpose
stays with the consumers (inside the loop as well: 0.21 → 0.24 ms). Its colour image and
mask are taken on the cut as it lies (contiguous reads of the three channels) and then
transposed, rather than computed from the transposed uint8 cut: that band's colour sum and
mask 0.25 → 0.19 ms alone (400 interleaved calls), the tracking frame 3.83 → 3.79,
3.52 → 3.45 and 2.69 → 2.66 ms median (`experiments.ab_tracking --rev` the cut above, 400,
500 and 600 interleaved frames, load 2.4–4.9); small, but in every run; identical outputs.
Both together against the fused cut (`experiments.ab_tracking --rev main`, load 4.4–5.1,
identical outputs): the tracking frame with band MED 3.41 → 3.16 ms median (600
interleaved frames), the tracker's configuration on video seed 555 2.90 → 2.65 ms
(``--program tracking --seed 555``, 400) and `Tracker.step` 3.10 → 2.73 ms
(``--program tracker``, 400). Not kept: ``jnp.any`` of the mask as one uint8 maximum of
the cut (XLA runs the boolean reduction as ``reduce-window`` kernels; alone, before the
cut's loop, the frame went 4.48 → 4.44 ms, 300 interleaved frames: noise), the cut as
the output of a `lax.cond` rather than a loop (the same time, 3.91 ms both), and
`frame_stats`'s sums as exact integer sums (0.140 → 0.073 ms alone, but the frame
3.18 → 3.28 ms, 400 interleaved frames: it runs beside the bands), and the band of
columns' colour image and mask passed to the fill's loop as they lie, transposed inside
it (the frame 3.02 → 3.18 ms, 400 interleaved frames, load 4.7–5.1).
"""

from __future__ import annotations

import jax.numpy as jnp
from jax import lax
from jaxtyping import Array, Float, UInt8

from ..segmentation.clipped import DOME_MIN_RUN, MAX_RUN, clipped_mask, fill_clipped, white_mask
from .small_ops import one_function

__all__ = [
    "band_image",
    "colour_sum",
    "frame_input",
    "frame_stats",
    "image_cutter",
    "rgb_cutter",
    "sheared_band",
    "STATS_STRIDE",
]

#: Every STATS_STRIDE-th row and column enters the frame's brightness and saturated share.
STATS_STRIDE = 4


def colour_sum(rgb: UInt8[Array, "h w 3"], weights, dtype) -> Float[Array, "h w"]:
    """Eq. (8), I = w_r R + w_g G + w_b B, as a channel-weighted sum over the static weights.

    Zero weights are skipped; the same values as ``rgb.astype(dtype) @ w`` (a matrix
    product over a length-3 axis), which XLA's CPU backend runs ≈ 3× slower
    (results/bench_speed.md).
    """
    out = None
    for c, w in enumerate(weights):
        if w == 0:
            continue
        term = rgb[..., c].astype(dtype)
        term = term if w == 1 else (-term if w == -1 else float(w) * term)
        out = term if out is None else out + term
    return jnp.zeros(rgb.shape[:-1], dtype) if out is None else out


def _fill(rgb, I, clip, weights, axis: int, dome: tuple, margin: int = 0):
    """`fill_clipped` of ``I`` along ``axis`` (rows ``margin .. n − margin`` only, axis 0).
    ``dome``: () for the flat fill, or (height
    along axis 0, height along axis 1, odd share, min run, colour, along) as
    `cslx.runtime.pipeline._dome` builds it: runs longer than min run (`DOME_MIN_RUN` when
    0) with at most that share of odd pixels (white, `white_mask`, when ``colour``; no
    clipped pixel ``along`` px to either side across ``axis`` when ``along`` > 0) are domed
    to 1 + height at their middle (issue 12; opt-in).

    The fill runs as one function (`cslx.runtime.small_ops.one_function`: its scan, the
    stacking of its inputs and outputs and the flank levels without a task each), the same
    values bit for bit: tracking bands with the tracker's domed fill, rows 0.632 → 0.504 ms,
    columns 0.749 → 0.607 ms median (300 interleaved calls on 12 frames of the sunny video,
    seed 0, load 2–4; issue 13)."""
    height = float(dome[axis]) if dome else 0.0
    if height <= 0:
        return one_function(
            lambda I, clip: fill_clipped(I, clip, axis=axis, margin=margin)[0], I, clip
        )
    _, _, share, min_run, colour, along = dome
    white = white_mask(rgb, weights) if colour else None

    def domed(I, clip, white):
        return fill_clipped(
            I,
            clip,
            axis=axis,
            white=white,
            dome=height,
            dome_min_run=int(min_run) or DOME_MIN_RUN,
            dome_white_share=float(share),
            dome_along=int(along),
            margin=margin,
        )[0]

    return one_function(domed, I, clip, white)


def _fill_inputs(sub, axis: int, weights, dtype, dome: tuple):
    """(cut, colour image, clipped mask, dome) of a band's uint8 cut with the fill's axis
    leading. For a band of columns (axis 1) the fill scans along the rows' axis with the
    columns leading: the uint8 cut is transposed once (and the finished band once), rather
    than the colour image, the mask and the fill's four flank arrays (the same values;
    480×128 band 2.04 → 1.38 ms, 400 interleaved calls, load 6, issue 13); the colour image
    and the mask are taken on the cut as it lies and transposed (module notes), and the
    dome's heights swapped (the fill along the transposed axis 0 is the frame's axis 1)."""
    I, clip = colour_sum(sub, weights, dtype), clipped_mask(sub)
    if axis == 1:
        I, clip = I.T, clip.T
        sub = jnp.transpose(sub, (1, 0, 2))
        dome = (dome[1], dome[0], *dome[2:]) if dome else dome
    return sub, I, clip, dome


def band_image(
    rgb: UInt8[Array, "h w 3"],
    start,
    size: int,
    axis: int,
    weights,
    dtype,
    fill: bool = True,
    dome: tuple = (),
) -> Float[Array, "a b"]:
    """Monochrome band of ``size`` samples from ``start`` along ``axis``, clipped runs filled.

    axis 0: rows ``start .. start + size`` (all columns; the horizontal stripe's band, filled
    down the columns); axis 1: columns (all rows; the vertical stripe's, filled along the
    rows). Equal to the same band of ``fill_clipped(colour_sum(rgb), clipped_mask(rgb),
    axis=axis)`` (module notes); ``fill=False`` cuts the colour image only.

    Away from the frame's border (the context fits on both sides) the fill's scans stop at
    the band's far edge (`fill_clipped`'s ``margin``): the same values with fewer steps
    (issue 13: band of rows alone 0.75 → 0.58 ms, of columns 0.71 → 0.69 ms, 300
    interleaved calls on video seed 555 at load 11; identical bands). With it the tracking
    frame went 6.07 → 5.49 ms (`experiments.ab_tracking --program tracking --seed 555`, 400
    interleaved frames, load 12–13) and `Tracker.step` 4.15 → 3.83 ms (300, load 9–11),
    outputs identical.
    """
    n = rgb.shape[axis]
    start = jnp.asarray(start, jnp.int32)
    zero = jnp.zeros((), jnp.int32)
    ctx = MAX_RUN + 1 if fill else 0
    outer = min(size + 2 * ctx, n)
    o0 = jnp.clip(start - ctx, 0, n - outer)
    starts = (o0, zero, zero) if axis == 0 else (zero, o0, zero)
    shape = list(rgb.shape)
    shape[axis] = outer
    if outer == n:  # the whole frame along the axis (o0 is 0)
        sub = rgb
    else:  # the cut as its own buffer, not fused into its consumers (module notes)
        # (`one_function`'s first argument must be a float array: its loop condition)
        sub = one_function(
            lambda o, x, s: lax.dynamic_slice(x, s, shape), o0.astype(dtype), rgb, starts
        )
    if not fill:
        return _sub_band(colour_sum(sub, weights, dtype), start - o0, size, axis)
    sub, I, clip, dome = _fill_inputs(sub, axis, weights, dtype, dome)

    def cut(x):
        return _sub_band(x, start - o0, size, 0)

    def full():
        return cut(_fill(sub, I, clip, weights, 0, dome))

    def inner():  # the context fits on both sides: the scans stop at the band's far edge
        return _fill(sub, I, clip, weights, 0, dome, ctx)

    def filled():
        if outer < size + 2 * ctx:
            return full()
        return lax.cond(start - o0 == ctx, inner, full)

    # Most frames have no clipped pixel in the band: skip the fill there (on the CPU
    # `lax.cond` runs one branch only).
    out = lax.cond(jnp.any(clip), filled, lambda: cut(I))
    return out.T if axis == 1 else out


def _lerp_rows(x, frac, ctx: int, size: int):
    """Rows ``ctx .. ctx + size`` of ``x`` moved down by ``frac`` (per column) of a row:
    (1 − f) x[ctx + r] + f x[ctx + r + 1], linear interpolation (`sheared_band`)."""
    frac = frac.astype(x.dtype)
    return (1 - frac) * x[ctx : ctx + size] + frac * x[ctx + 1 : ctx + size + 1]


def sheared_band(
    rgb: UInt8[Array, "h w 3"],
    start: Float[Array, " n"],
    size: int,
    axis: int,
    weights,
    dtype,
    fill: bool = True,
    dome: tuple = (),
) -> Float[Array, "a b"]:
    """A band that follows a leaning stripe: `band_image` with a start per column (row).

    axis 0: for every column u the ``size`` rows from ``start[u]`` (a float row, within
    [0, H − size − 1]); axis 1: for every row v the ``size`` columns from ``start[v]``.
    Band sample r of column u is the frame's monochrome input (colour sum, clipped runs
    filled down the column) at row ``start[u] + r``, linearly interpolated between the rows
    ⌊start[u]⌋ + r and ⌊start[u]⌋ + r + 1 (issue 13: a shear by whole rows would make the
    leaning stripe a staircase in the band, and Steger's smoothing along it would move the
    centres by up to ½ px towards the neighbouring columns; interpolated, the stripe runs
    straight along the band). At a whole-row start the band is the frame's input exactly.

    Each column's rows are gathered with ``MAX_RUN + 1`` rows of context on both sides,
    indices clamped at the frame's border (the border row repeated). The fill works down
    each column alone (the tracker's dome has no ``along`` test), so as in `band_image` the
    context holds every clipped run reaching into the band with its flanks; a run touching
    the frame's border still touches the cut's edge after the repeated rows, and is left
    unfilled in both (tests/runtime/test_band_input.py).
    """
    n = rgb.shape[axis]
    ctx = MAX_RUN + 1 if fill else 0
    outer = size + 1 + 2 * ctx
    first = jnp.floor(start)
    frac = start - first
    rows = (
        first.astype(jnp.int32)[None, :] + jnp.arange(-ctx, outer - ctx, dtype=jnp.int32)[:, None]
    )
    rows = jnp.clip(rows, 0, n - 1)  # (outer, N)
    if axis == 0:
        sub = jnp.take_along_axis(rgb, rows[:, :, None], axis=0)  # (outer, W, 3)
    else:
        sub = jnp.take_along_axis(rgb, rows.T[:, :, None], axis=1)  # (H, outer, 3)
    sub, I, clip, dome = _fill_inputs(sub, axis, weights, dtype, dome)
    if fill:  # the fill's scans stop at the band's far edge (``margin``, as in `band_image`)
        I = lax.cond(
            jnp.any(clip),
            lambda: _fill(sub, I, clip, weights, 0, dome, ctx),
            lambda: I[ctx : ctx + size + 1],
        )
    out = _lerp_rows(I, frac, 0, size)
    return out.T if axis == 1 else out


def _sub_band(x, offset, size: int, axis: int):
    """``size`` samples of ``x`` from ``offset`` along ``axis`` (all of ``x`` when it fits)."""
    if x.shape[axis] == size:
        return x
    return lax.dynamic_slice_in_dim(x, offset, size, axis=axis)


def frame_stats(rgb: UInt8[Array, "h w 3"], dtype, stride: int = STATS_STRIDE):
    """(mean grey level 0..255, share of pixels with a channel at 255) of a frame.

    Taken on every ``stride``-th row and column: the tracker's frame gates compare them
    with thresholds (3 grey levels, 50 % clipped), which a 1/16 subsample of 640×480
    (19 200 pixels) resolves; the full frame cost ≈ 1 ms a frame.
    """
    sub = rgb[::stride, ::stride]
    return jnp.mean(sub.astype(dtype)), jnp.mean(jnp.any(sub >= 255, axis=-1).astype(dtype))


def frame_input(
    rgb: UInt8[Array, "h w 3"],
    weights,
    dtype,
    fill: bool = True,
    dome: tuple = (),
):
    """The whole frame's monochrome input: one image, or (filled down the columns, filled
    along the rows) when ``fill`` (one image per stripe axis)."""
    I = colour_sum(rgb, weights, dtype)
    if fill:
        # clipped pixels hold lower bounds: fill each short run along the stripe's search
        # axis from its flanks (`cslx.segmentation.clipped.fill_clipped`), one image per stripe
        clip = clipped_mask(rgb)
        I = tuple(_fill(rgb, I, clip, weights, a, dome) for a in (0, 1))
    return I


def image_cutter(I):
    """``cut(axis, start, size)``: a band of converted whole-frame input (`frame_input`);
    a float vector ``start`` (one per column / row) cuts a sheared band (`sheared_band`)."""
    I_h, I_v = I if isinstance(I, tuple) else (I, I)
    zero = jnp.zeros((), jnp.int32)

    def cut(axis, start, size):
        if jnp.ndim(start) == 1:
            x = I_h if axis == 0 else I_v.T
            first = jnp.floor(start)
            rows = first.astype(jnp.int32)[None, :] + jnp.arange(size + 1, dtype=jnp.int32)[:, None]
            sub = jnp.take_along_axis(x, jnp.clip(rows, 0, x.shape[0] - 1), axis=0)
            out = _lerp_rows(sub, start - first, 0, size)
            return out.T if axis == 1 else out
        if axis == 0:
            return lax.dynamic_slice(I_h, (start, zero), (size, I_h.shape[1]))
        return lax.dynamic_slice(I_v, (zero, start), (I_v.shape[0], size))

    return cut


def rgb_cutter(
    rgb: UInt8[Array, "h w 3"],
    weights,
    dtype,
    fill: bool = True,
    dome: tuple = (),
):
    """``cut(axis, start, size)``: a band cut from the RGB frame and converted (`band_image`,
    or `sheared_band` for a float vector ``start``); the same values as
    ``image_cutter(frame_input(rgb, ...))``."""

    def cut(axis, start, size):
        if jnp.ndim(start) == 1:
            return sheared_band(rgb, start, size, axis, weights, dtype, fill, dome)
        return band_image(rgb, start, size, axis, weights, dtype, fill, dome)

    return cut
