"""Chroma-subsampled frames (real-camera formats): the test, and the full-resolution signal.

Rendered frames are full-resolution RGB; real cameras rarely deliver that. Webcams stream
MJPEG (JPEG: YCbCr with the chroma sampled 4:2:0, i.e. at half resolution both ways) or
YUYV (4:2:2, half resolution horizontally), photos are JPEG 4:2:0, and JPEG's chroma
quantisation removes the fine chroma detail at any quality. For a red laser on a grey
board the colour space the kurtosis search picks (R − G = 0.344 Cb + 2.116 Cr in JFIF
YCbCr) is pure chroma: in such a frame the stripe's profile across it is sampled at half
resolution, blurred and aliased by the phase of the stripe on the 2-pixel chroma grid,
while the luma Y = 0.299 R + 0.587 G + 0.114 B keeps every pixel.

The test (`subsampled`). Chroma interpolated from half resolution (repeated over pixel
pairs by YUYV decoders, linearly by libjpeg's "fancy" upsampling) has no energy at the
Nyquist frequency of the full grid, and JPEG's chroma quantisation zeroes it in the flat
blocks; a full-resolution sensor's chroma carries its noise there. Along the profile's
axis (image axis 0 for the horizontal stripe, 1 for the vertical), the frame is cut into
windows of `WINDOW` pixels aligned with the grid and each window's Nyquist coefficient
Σₙ (−1)ⁿ c(n) / √`WINDOW` is taken of Cb and Cr; the median over the windows of their
summed squares is the chroma's Nyquist power (DN², per pixel: the noise variance for white
noise), robust to the stripe and to edges. Below `NYQUIST_FLOOR` the chroma counts as
subsampled. Development frames (seeds 7100–7117 frame 0, flat walls 61–64 saturated, sunny
and green; `experiments/chroma_subsampling.py`), both axes: rendered PNG 1.67–5.0 DN²
(read and shot noise), YUYV horizontal 0.035 (8-bit rounding; vertical 1.0–2.8, full
resolution as it should be), JPEG 4:2:0 at quality 95 / 85 / 70 and 4:4:4 at 70: 0 on
every frame. A noise-free synthetic frame has no chroma noise either, and is treated as
subsampled: its luma holds the stripe at full resolution as well.

The signal (`luma`). Where the chroma is subsampled, the colour space still finds the
stripe (first pass of `cslx.segmentation.robust`); the second pass re-measures the centres
on a full-resolution signal. The only one is Y (every RGB channel is Y plus a chroma term:
R = Y + 1.402 Cr puts 70 % of a red laser's R contrast in the blurred Cr). It is used where
at least `robust.CHROMA_SATURATED` (0.5) of the path is saturated, its second-pass centres
averaged with the colour space's (`robust.CHROMA_BLEND` 0.5). Evidence (development frames
as above, 18 robust + 12 flat; H / V; median / p95 mm, flat-wall RMS px), no change → this:
YUYV V 0.043 / 3.54, 0.169 → 0.056 / 2.93, 0.083 (H untouched); JPEG 4:2:0 q95 H 0.048 /
0.247, 0.076 → 0.049 / 0.242, 0.056, V 0.048 / 0.257, 0.089 → 0.053 / 0.234, 0.056; q85 H
0.076 / 0.492, 0.088 → 0.065 / 0.455, 0.069, V 0.050 / 0.343, 0.118 → 0.055 / 0.324, 0.077;
q70 H 0.118 / 0.669, 0.141 → 0.096 / 0.619, 0.097, V 0.073 / 0.483, 0.116 → 0.076 /
0.477, 0.094; 4:4:4 q70 H 0.056 / 0.349, 0.097 → 0.061 / 0.299, 0.072, V 0.055 / 0.298,
0.169 → 0.060 / 0.284, 0.112. Gross (> 1 mm) shares fall or stay (q70 H 2.03 → 1.69 %).
Tried and not kept: the luma alone on every subsampled frame (flat walls gain as much, but
sunlit, printed and blue frames lose: q95 median 0.066 / 0.099, q70 0.088 / 0.105 mm — the
luma carries the white sunlight, sheen, glints and print that R − G cancels); the luma
alone where the path is saturated (q70 H 0.099, V 0.089 mm), the same divided by the
reflectance (0.099, 0.084); the laser's own channel (R for red) on every subsampled frame
(q95 H 0.056 mm against the luma's 0.066 and no change's 0.048); the average with the
luma on every subsampled frame (q95 V median 0.061, q70 H 0.080 / V 0.079 mm; flat walls
as with the gate). Cost: the test 2 ms per frame and stripe (load 20), on every frame; the
luma's extra second pass where used (tens of ms under that load).

Precision weights instead of the fixed 0.5 (tried, not kept; JPEG pipelines, development
frames as above, one run with the fixed blend as baseline, load ≈ 4). Each path's scatter
about its smooth path, s² = mean d² / 1.5 of the second difference at lag L (the
`ridges._path_scatter` estimate, mean square), weights ∝ 1 / s². Per centre (s² over ±40
centres, L 12) flat q85 H / V RMS 0.069 / 0.077 → 0.078 / 0.068 px (±120: 0.068 / 0.076),
dropped. Per stripe, q85 flat, L 6 / 12 / 24: 0.067 / 0.073, 0.066 / 0.069, 0.066 / 0.067.
L 24 on everything, fixed → weighted (flat RMS H / V px; development median / p95 mm H, V):
q95 0.056 / 0.056 → 0.057 / 0.055, H 0.0494 / 0.242 → 0.0495 / 0.241, V 0.0533 / 0.234
→ 0.0510 / 0.237; q85 0.069 / 0.077 → 0.066 / 0.067, H 0.0646 / 0.455 → 0.0665 / 0.469,
V 0.0522 / 0.259 → 0.0546 / 0.269; q70 0.097 / 0.094 → 0.089 / 0.085, H 0.0943 / 0.549
→ 0.0995 / 0.549 (gross 1.25 → 1.45 %), V 0.0721 / 0.459 → 0.0679 / 0.463; 4:4:4 q70 H
flat 0.072 → 0.074, V median 0.0602 → 0.0629 (gross 0.30 → 0.56 %). The flat walls gain,
the development frames lose at q85 and q70 H: the scatter sees noise, not the luma's
smooth biases (sun, sheen, print). The luma's weight clipped to ≤ 0.5: q85 flat 0.068 /
0.076, H 0.0659 / 0.469, q70 H 0.1002 / 0.553; to 0.35–0.65: q85 flat 0.066 / 0.070, H
0.0658 / 0.469, V 0.0544 / 0.268, q70 flat 0.092 / 0.088, H 0.0943 / 0.545 (gross 1.38
%), V 0.0687 / 0.458 — the flat walls' gain always costs q85's development frames.

Clipped cores in 4:2:2 (`clipped_pairs`, `PAIR_MARGIN`). A YUYV decoder adds the chroma
shared by a pixel pair to each pixel's luma; inside a clipped red core, where G and B rise
steeply towards the white middle, the two pixels of a pair differ in Cr, so one of them
reads R below the clip level (development frame 7114, saturated in sun: of the pixels
clipped in the rendered frame, 1 / 5 / 10 / 25 % read at most 239 / 245 / 248 / 253 after
YUYV; single pixels inside the core down to 235). The clipped run then breaks into pieces,
each filled on its own (`fill_clipped`): several bumps instead of one, and across the
vertical stripe the linked path left the stripe (both saturated-sunny development frames: ≈
3.5 mm off on 8.8 % of the centres, since then dropped whole by the no-stripe test:
detection 88.89 %). On a 4:2:2 frame (`formats`: `subsampled` along one axis only), both
stripes, a pixel counts as clipped within `PAIR_MARGIN` DN of the clip level, or within
`PAIR_GAP` DN between two such pixels; the luma is not averaged in there (it was a remedy
for the broken core: with the core whole it made the V stripe worse). YUYV, V stripe,
development frames as above (detection %, median / p95 mm, flat RMS / worst px), before →
margin 16 with the luma → margin 16 without (default): 88.89, 0.049 / 0.207, 0.083 / 0.189 →
99.93, 0.060 / 0.210, 0.077 / 0.176 → 99.93, 0.040 / 0.169, 0.063 / 0.107. Margin 10 / 13 /
22 without the luma: 99.85 / 94.39 / 99.93 %, 0.043 / 0.041 / 0.043 mm median, flat 0.046 /
0.060 / 0.055 px — at 13 frame 7114 is lost again (a 240 inside its core), so the margin
alone is fragile. Closing one-pixel gaps within `PAIR_GAP` 32 DN (default) made it robust
and better on every figure: margin 16 / 13, 99.91 / 99.91 %, 0.039 / 0.037 mm median, p95
0.159 / 0.158 mm, flat 0.049 / 0.049 px RMS, worst 0.081 / 0.080 (no gross centre in any
variant). The horizontal stripe (its profile full-resolution, but a clipped core's pixels
paired with their neighbours along it) gains as much: development frames, before → widened
test, detection 100 %, median / p95 0.037 / 0.163 → 0.032 / 0.133 mm, flat RMS / worst 0.092
/ 0.136 → 0.035 / 0.060 px. JPEG keeps the clip level: 4:2:0 is subsampled both ways, and
the margin did not pay there (q85 flat walls H / V 0.069 / 0.077 px → 0.074 / 0.083 with the
luma, 0.075 / 0.071 without; margin 28 lost a flat wall's H stripe): JPEG's quantisation
takes clipped cores lower (flat wall 61, q85: median 251, 5 % ≤ 223) and rings sunlit
neighbours up. Rendered and JPEG outputs are unchanged bit for bit (the test gates it;
checked on PNG and JPEG 4:2:0 q85 for frames 7102, 7115 and flat walls 61, sunny 62; JPEG
4:2:0 q95 / q70 and 4:4:4 q70 for 7115 and sunny 62). Cost: the test runs on both axes for
every frame and stripe (2 ms each, load 20).

Pure JAX, jit-able.
"""

from __future__ import annotations

import functools

import jax
import jax.numpy as jnp
import numpy as np

from .clipped import clipped_mask, fill_clipped
from .ridges import _median

__all__ = [
    "LINE_STRIDE",
    "LUMA",
    "NYQUIST_FLOOR",
    "PAIR_GAP",
    "PAIR_MARGIN",
    "WINDOW",
    "chroma_nyquist",
    "clipped_pairs",
    "formats",
    "luma",
    "pair_margins",
    "saturated_share",
    "second_signal",
    "subsampled",
]

#: JFIF (ITU-R BT.601) luma and chroma weights of R, G, B.
LUMA = (0.299, 0.587, 0.114)
_CB = (-0.168736, -0.331264, 0.5)
_CR = (0.5, -0.418688, -0.081312)
#: Window (px) of the Nyquist coefficient: the JPEG block, a multiple of the chroma pairs.
WINDOW = 8
#: Lines (across the windows' axis) used by the test: every `LINE_STRIDE`-th.
LINE_STRIDE = 4
#: Chroma Nyquist power (DN², per pixel) below which the chroma counts as subsampled. The
#: geometric middle of YUYV's 0.035 and the quietest full-resolution frames seen: the demo
#: rig's renders (`cslx demo`, 800 × 640, a quieter sensor) score 0.31–0.96 (clean 0.31),
#: the development frames 1.6–5.0; JPEG 0.000. (0.25 at first: ×1.25 from the demo's.)
NYQUIST_FLOOR = 0.1
#: 4:2:2 clipped cores (`clipped_pairs`, module docstring): a channel within `PAIR_MARGIN`
#: DN of the clip level counts as clipped, within `PAIR_GAP` DN between two such pixels
#: (0: the 4:2:2 handling off; `PAIR_GAP` ≤ `PAIR_MARGIN`: the margin alone).
PAIR_MARGIN = 16.0
PAIR_GAP = 32.0


def chroma_nyquist(image, axis: int):
    """Median over `WINDOW`-pixel windows along image axis `axis` of the chroma's (Cb + Cr)
    Nyquist power (DN² per pixel; module docstring). (H, W, 3) RGB, 8-bit scale."""
    x = jnp.asarray(image)
    if not jnp.issubdtype(x.dtype, jnp.floating):
        x = x.astype(jnp.result_type(float))
    if axis == 0:
        x = jnp.swapaxes(x, 0, 1)
    x = x[::LINE_STRIDE]  # every 4th line across the windows: a quarter of the cost
    h, w = x.shape[:2]
    n = (w // WINDOW) * WINDOW
    weights = jnp.asarray(np.stack([_CB, _CR], 1), x.dtype)  # (3, 2)
    c = x[:, :n] @ weights  # (h, n, 2)
    sign = jnp.asarray((-1.0) ** np.arange(WINDOW) / np.sqrt(WINDOW), x.dtype)
    coef = jnp.einsum("hkwc,w->hkc", c.reshape(h, n // WINDOW, WINDOW, 2), sign)
    power = jnp.sum(coef**2, axis=-1).reshape(-1)
    return _median(power)


@functools.partial(jax.jit, static_argnames=("axis",))
def _subsampled(image, floor, *, axis: int):
    return chroma_nyquist(image, axis) < floor


def subsampled(image, axis: int, floor: float = NYQUIST_FLOOR) -> bool:
    """True when the frame's chroma has no noise at the Nyquist frequency along image axis
    `axis` (0: vertical, the horizontal stripe's profile; 1: horizontal): it was subsampled
    (4:2:0 / 4:2:2) or compressed (module docstring). (H, W, 3) RGB, 8-bit scale."""
    return bool(_subsampled(jnp.asarray(image), floor, axis=axis))


def formats(image, axis: int) -> tuple[bool, bool]:
    """(chroma subsampled along image axis `axis`; 4:2:2: subsampled along one axis only,
    and `PAIR_MARGIN` set) of an (H, W, 3) RGB frame (`subsampled`)."""
    along = np.asarray(_subsampled_both(jnp.asarray(image), NYQUIST_FLOOR)).tolist()
    return along[axis], bool(PAIR_MARGIN) and along[0] != along[1]


@jax.jit
def _subsampled_both(image, floor):
    """`subsampled` along both image axes in one program and one transfer to the host."""
    return jnp.stack([chroma_nyquist(image, 0), chroma_nyquist(image, 1)]) < floor


def pair_margins() -> tuple[float, float]:
    """(`PAIR_MARGIN`, `PAIR_GAP`), the static margins of `clipped_pairs`."""
    return float(PAIR_MARGIN), float(PAIR_GAP)


def luma(image):
    """(H, W) JFIF luma Y of an (H, W, 3) RGB frame: the one full-resolution signal of a
    chroma-subsampled frame."""
    return jnp.asarray(image) @ jnp.asarray(LUMA, jnp.asarray(image).dtype)


@functools.partial(jax.jit, static_argnames=("axis", "variant", "max_run"))
def second_signal(image, weights, clip_level, *, axis: int, variant: str, max_run: int):
    """The second pass's monochrome image of a chroma-subsampled frame, clipped runs filled
    as in the first (`cslx.segmentation.clipped.fill_clipped`). `variant`: "luma" (Y),
    "luma-div" (Y divided by the reflectance as `robust._reflectance_divided`), "channel"
    (the RGB channel of the colour space's largest weight `weights`)."""
    from .robust import _reflectance_divided

    clipped = clipped_mask(image, clip_level)
    if variant == "channel":
        mono = jnp.take(image, jnp.argmax(weights), axis=-1)
    else:
        mono = luma(image)
    if variant == "luma-div":
        mono = _reflectance_divided(image, mono, clipped)
    return fill_clipped(mono, clipped, axis=axis, max_run=max_run)[0]


def clipped_pairs(image, clip_level, *, axis: int, margins: tuple = ()):
    """`clipped_mask`, or with `margins` (m, g) that of a 4:2:2 frame along image axis `axis`
    (module docstring): a channel within m DN of `clip_level`, or within g DN with such
    pixels on both sides along `axis` (a one-pixel gap in a clipped core)."""
    if not margins:
        return clipped_mask(image, clip_level)
    soft = clipped_mask(image, clip_level - margins[0])
    loose = clipped_mask(image, clip_level - margins[1])
    pad = [(0, 0), (0, 0)]
    pad[axis] = (1, 1)
    sp = jnp.pad(soft, pad)
    n = soft.shape[axis]
    before = jax.lax.slice_in_dim(sp, 0, n, axis=axis)
    after = jax.lax.slice_in_dim(sp, 2, n + 2, axis=axis)
    return soft | (loose & before & after)


def saturated_share(saturated, valid) -> float:
    """Share of the valid centres flagged saturated (a clipped core or a bridge)."""
    v = np.asarray(valid)
    return float(np.mean(np.asarray(saturated)[v])) if v.any() else 0.0
