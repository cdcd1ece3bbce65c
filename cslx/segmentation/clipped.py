"""Clipped (saturated) stripe cores: the mask, and the fill from the unclipped flanks.

A laser core brighter than the sensor's range is a plateau at the clip level, 3–15 px wide
on this rig (more on sunlit bead flanks); Steger's detector finds no ridge on a plateau
wider than its bar limit √3·σ. `fill_clipped` replaces every clipped run along the search
axis (up to `MAX_RUN` px, not touching the border) by a level from its two flanks, flat
by default or, opt-in, domed (a parabola with its top at the run's middle; issue 12). Used
by the linked detector (`cslx.segmentation.robust`) and the pipeline's input
(`cslx.runtime.band_input`).
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
from jax import lax

from ..config import CLIP_LEVEL

__all__ = ["DOME_MIN_RUN", "MAX_RUN", "centre_runs", "clipped_mask", "fill_clipped", "white_mask"]

#: Longest clipped run (px along the search axis) treated as a saturated laser core.
MAX_RUN = 24
#: Clipped runs longer than this (px) may be domed (`fill_clipped`'s ``dome``): Steger's
#: bar limit √3·σ at σ 2; shorter flat runs already give one ridge at their middle.
DOME_MIN_RUN = 3


def clipped_mask(image, clip_level: float = CLIP_LEVEL):
    """(H, W) True where any channel of an 8-bit-scaled RGB frame is at `clip_level` or above."""
    channels = jnp.unstack(jnp.asarray(image), axis=-1)  # no reduction over the minor axis
    return functools.reduce(jnp.maximum, channels) >= clip_level


def white_mask(image, weights, clip_level: float = CLIP_LEVEL):
    """(H, W) True where a channel that is not the laser's (weight ≤ 0 in ``weights``, static)
    is at `clip_level` or above: a glint or sun-whitened pixel, not a laser-only clip."""
    channels = jnp.unstack(jnp.asarray(image), axis=-1)
    others = [ch for ch, w in zip(channels, weights, strict=True) if float(w) <= 0]
    if not others:
        return jnp.zeros(channels[0].shape, bool)
    return functools.reduce(jnp.maximum, others) >= clip_level


def centre_runs(rgb, pos, valid, weights, *, axis: int = 0, half: int = MAX_RUN // 2):
    """The clipped run through each stripe centre: its length (px) and whether it is white.

    Args:
        rgb: (H, W, 3) 8-bit-scaled frame. pos: (N,) sub-pixel centres along ``axis`` (the
            row of each column for axis 0, the horizontal stripe; the column of each row for
            axis 1), frame coordinates. valid: (N,) which centres exist.
        weights: the colour weights (static); a channel weighted ≤ 0 is not the laser's.
        half: the run is followed this many px to either side of the centre's pixel (a
            longer run counts 2·half + 1).
    Returns:
        (length (N,) int32: the run of pixels clipped in any channel that holds the centre's
        pixel, 0 where that pixel is not clipped or the centre is not valid; white (N,)
        bool: a pixel of that run is clipped in a channel that is not the laser's,
        `white_mask`). A centre on a run longer than Steger's bar limit lies where the fill
        (`fill_clipped`) put its ridge, not where the stripe's light was measured.
    """
    img = jnp.asarray(rgb)
    if axis == 1:
        img = jnp.transpose(img, (1, 0, 2))
    n = img.shape[0]
    r0 = jnp.round(jnp.where(valid, pos, -1e6)).astype(jnp.int32)
    k = jnp.arange(-half, half + 1, dtype=jnp.int32)
    rows = r0[None, :] + k[:, None]  # (2·half + 1, N)
    inside = (rows >= 0) & (rows < n)
    cols = jnp.arange(img.shape[1], dtype=jnp.int32)[None, :]
    px = img[jnp.clip(rows, 0, n - 1), cols]  # (2·half + 1, N, 3)
    clip = clipped_mask(px) & inside
    white = white_mask(px, weights) & inside
    up = jnp.cumprod(clip[half::-1].astype(jnp.int32), axis=0)  # the run from the centre up
    down = jnp.cumprod(clip[half:].astype(jnp.int32), axis=0)
    length = jnp.sum(up, axis=0) + jnp.sum(down, axis=0) - clip[half].astype(jnp.int32)
    in_run = jnp.concatenate([up[::-1][:-1], down], axis=0).astype(bool)
    return length, jnp.any(white & in_run, axis=0)


def background_step(rgb, pos, valid, weights, gap: int):
    """Per horizontal-stripe centre: how much the background changes across the stripe.

    The colour image of Eq. (8) subtracts the channels weighted < 0 (G in R − G) as the
    ambient light's estimate under the laser's channel. Where a shadow edge (or a glint)
    crosses the stripe, those channels step from one side of the stripe to the other, the
    subtraction no longer cancels the background, and with the laser's channel clipped the
    colour image's ridge follows the edge rather than the light (rendered shadow, issue 12:
    dev seed 7305, beside, frames 1–7, bead-flank centres 0.4–1.4 mm low in height, the bead
    1 mm off). Returns (N,) |b(r + gap) − b(r − gap)| / max(laser channels at r, 1): b the
    sum of the subtracted channels (|weight| each; all channels when none is subtracted),
    r the centre's row, sampled ``gap`` px beyond it to each side (rows clamped to the
    frame); 0 where the centre is not valid.
    """
    img = jnp.asarray(rgb).astype(jnp.float32)
    n = img.shape[0]
    neg = [(-w if w < 0 else 0.0) for w in weights]
    pos_w = [(w if w > 0 else 0.0) for w in weights]
    bw = jnp.asarray(neg if any(neg) else [1.0, 1.0, 1.0], jnp.float32)
    lw = jnp.asarray(pos_w if any(pos_w) else [1.0, 1.0, 1.0], jnp.float32)
    r0 = jnp.round(jnp.where(valid, pos, 0.0)).astype(jnp.int32)
    cols = jnp.arange(img.shape[1], dtype=jnp.int32)

    def at(rows, w):
        return img[jnp.clip(rows, 0, n - 1), cols] @ w

    step = jnp.abs(at(r0 + gap, bw) - at(r0 - gap, bw))
    return jnp.where(valid, step / jnp.maximum(at(r0, lw), 1.0), 0.0)


@functools.partial(
    jax.jit,
    static_argnames=(
        "axis",
        "max_run",
        "dome",
        "dome_min_run",
        "dome_white_share",
        "dome_along",
        "margin",
    ),
)
def fill_clipped(
    mono,
    clipped,
    *,
    axis: int = 0,
    max_run: int = MAX_RUN,
    white=None,
    dome: float = 0.0,
    dome_min_run: int = DOME_MIN_RUN,
    dome_white_share: float = 0.0,
    dome_along: int = 0,
    margin: int = 0,
):
    """Fill runs of clipped pixels along `axis` (≤ `max_run` long) from their flanks.

    Returns (filled image, (H, W) bool mask of the filled pixels). A run touching the image
    border or longer than `max_run` is left as it is.

    ``dome`` > 0 (opt-in; issue 12): a run longer than ``dome_min_run`` whose ``white``
    pixels (None: none; e.g. `white_mask`) plus, with ``dome_along`` > 0, pixels with no
    clipped pixel ``dome_along`` px to either side across ``axis`` make at most
    ``dome_white_share`` of it gets 1.5 × flank × (1 + dome · 4u(1 − u)), u ∈ (0, 1) the
    position between its flanks: a ridge at the run's middle instead of a plateau, which
    Steger does not see when the run is longer than √3·σ (sunlit bead flanks clip over
    8–14 rows). The default path (dome 0) is unchanged.

    The nearest unclipped index and value above and below every pixel come from one
    `lax.scan` along ``axis`` (both directions at once). XLA's CPU cumulative max transposes
    to scan along the minor axis and then needs gathers for the flank values: that cost the
    114×640 tracking band of rows 1.56 ms against 0.43 ms, a 480×640 frame 6.4 against
    2.0 ms, the 480×178 band of columns 1.24 against 0.99 ms (issue 13, load 4–5.6, same
    runs; the columns are scanned on the transposed band). Recursive doubling limited to the
    window a fill needs (a flank farther than ``max_run`` rows means a run left as it is:
    ⌈log₂(max_run + 1)⌉ = 5 elementwise steps per direction instead of one per row, masks
    identical, values to 1 ulp) was slower too: the tracking bands' cuts with the fill
    h 0.40 → 1.01 ms, v 0.65 → 1.41 ms with an `optimization_barrier` per step (300
    interleaved calls, load 8; without it XLA fused the steps and recomputed the shifted
    operands, the tracking frame 10.3 → 18.4 ms): ten passes over the band through memory
    against one pass whose (2, W) carry stays in cache (issue 13). The scan unrolled 8 steps
    a trip (`lax.scan(..., unroll=8)`) cut the tracking frame's executed kernels 8 468 →
    7 338 but took it 8.45 → 11.60 ms (300 interleaved frames, `experiments.ab_tracking`,
    load 5–6). The scan alone costs in proportion to its width (114 rows with margin 25,
    random mask: 640 columns 281 µs p10, 160 columns 96, 64 columns 72; load 7), but
    scanning only the columns, or the rows, that hold a clipped pixel would not shorten it
    on the sunny video (issue 13): 584–629 of the band of rows' 640 columns hold one (seed
    0, 11 tracking frames), and all of its 114 rows and of the band of columns' 178 columns
    (seeds 0, 1, 555, every tracking frame), the other stripe's clipped core crossing each
    band.

    ``margin`` (static; axis 0 only): return only samples ``margin .. n − margin`` along the
    axis (e.g. a tracking band cut with context, `cslx.runtime.band_input`), the same values
    as the full result's window: the scan down stops at the window's end and the scan up at
    its start (n − margin steps instead of n), and the fill is evaluated on the window only.
    """
    c = jnp.asarray(clipped)
    n = mono.shape[axis]
    w = jnp.asarray(white) if dome > 0 and white is not None else None
    if dome > 0 and dome_along > 0:
        # a pixel whose row (column) is clipped neither ``dome_along`` px before nor after it
        # across ``axis`` is no part of a stripe's core elongated along the stripe: it counts
        # as white
        other = 1 - axis
        pad = [(0, 0), (0, 0)]
        pad[other] = (dome_along, dome_along)
        cp = jnp.pad(c, pad)
        n_o = c.shape[other]
        before = lax.slice_in_dim(cp, 0, n_o, axis=other)
        after = lax.slice_in_dim(cp, 2 * dome_along, 2 * dome_along + n_o, axis=other)
        lone = ~(before | after)
        w = lone if w is None else (w | lone)
    if margin:
        if axis != 0:
            raise ValueError("margin needs axis 0")
        out = _flanks_rows(mono, c, w, margin)
        mono, c = mono[margin : n - margin], c[margin : n - margin]
    elif axis == 0:
        out = _flanks_rows(mono, c, w)
    else:
        out = tuple(x.T for x in _flanks_rows(mono.T, c.T, None if w is None else w.T))
    above, fa, below, fb = out[:4]
    length = below - above - 1
    inner = (above >= 0) & (below < n)
    run = c & inner & (length <= max_run)
    level = 1.5 * jnp.maximum(jnp.maximum(fa, fb), 0.0)
    if dome > 0:
        # a run longer than ``dome_min_run`` with at most ``dome_white_share`` of its pixels
        # ``white`` gets a parabola over the flat level, 1 + dome at its middle
        i = lax.broadcasted_iota(jnp.int32, mono.shape, axis) + margin
        u = (i - above).astype(mono.dtype) / jnp.maximum(below - above, 1).astype(mono.dtype)
        stripe = length > dome_min_run
        if w is not None:
            stripe = stripe & (out[4] <= dome_white_share * length)
        level = level * (1.0 + jnp.where(stripe, dome * 4.0 * u * (1.0 - u), 0.0))
    return jnp.where(run, level, mono), run


def _window(index, value, margin):
    """Rows margin .. n − margin of the scan's outputs (n − margin steps: down, up)."""
    k = index.shape[0] - margin
    return index[margin:, 0], value[margin:, 0], index[::-1, 1][:k], value[::-1, 1][:k]


def _flanks_rows(m, c, white=None, margin=0):
    """Per pixel: the last unclipped row ≤ i and its value, the first ≥ i and its value
    (-1 / n and 0 where there is none), in one scan down and up the rows at once.

    The two directions travel stacked, (2, W) per step: 2 slices in and 2 updates out a
    step instead of 5 and 4 (issue 13: same outputs; 400 interleaved calls at load 5, the
    114×640 band of rows 0.76 → 0.70 ms, the 480×178 band of columns 1.96 → 1.64 ms).
    """
    n, w = m.shape
    if white is not None:
        return _flanks_rows_white(m, c, white, margin)

    def step(carry, xs):
        k, index, value = carry
        clipped, mono = xs
        here = jnp.stack([k, n - 1 - k])[:, None]
        index, value = jnp.where(clipped, index, here), jnp.where(clipped, value, mono)
        return (k + 1, index, value), (index, value)

    start = jnp.broadcast_to(jnp.asarray([-1, n], jnp.int32)[:, None], (2, w))
    init = (jnp.zeros((), jnp.int32), start, jnp.zeros((2, w), m.dtype))
    k = n - margin
    xs = (jnp.stack([c[:k], c[::-1][:k]], 1), jnp.stack([m[:k], m[::-1][:k]], 1))
    _, (index, value) = lax.scan(step, init, xs)
    return _window(index, value, margin)


def _flanks_rows_white(m, c, white, margin=0):
    """`_flanks_rows` plus, per pixel, how many ``white`` pixels its clipped run holds (one
    count carried down and one up the rows, reset by an unclipped pixel: their sum less the
    pixel's own)."""
    n, w = m.shape

    def step(carry, xs):
        k, index, value, seen = carry
        clipped, mono, wh = xs
        here = jnp.stack([k, n - 1 - k])[:, None]
        index, value = jnp.where(clipped, index, here), jnp.where(clipped, value, mono)
        seen = jnp.where(clipped, seen + wh, 0)
        return (k + 1, index, value, seen), (index, value, seen)

    start = jnp.broadcast_to(jnp.asarray([-1, n], jnp.int32)[:, None], (2, w))
    zero = jnp.zeros((2, w), jnp.int32)
    init = (jnp.zeros((), jnp.int32), start, jnp.zeros((2, w), m.dtype), zero)
    wh = white.astype(jnp.int32)
    k = n - margin
    xs = (
        jnp.stack([c[:k], c[::-1][:k]], 1),
        jnp.stack([m[:k], m[::-1][:k]], 1),
        jnp.stack([wh[:k], wh[::-1][:k]], 1),
    )
    _, (index, value, seen) = lax.scan(step, init, xs)
    n_white = seen[margin:, 0] + seen[::-1, 1][: k - margin] - wh[margin:k]
    return (*_window(index, value, margin), n_white)
