"""A simple stripe-centre extractor for laser-plane calibration (`method="simple"`).

Used by `cslx.calibration` with `method="simple"` (`cslx.segmentation.extract` otherwise).
The calibration images are well lit boards with a bright red stripe, so a plain detector suffices:

1. I = R − G (a red laser on a grey board), Gaussian-smoothed (σ px), zero outside a mask;
2. per column (horizontal stripe) or per row (vertical stripe): the maximum, refined to
   sub-pixel by a parabola through it and its two neighbours;
3. a centre is kept when its peak exceeds `rel_threshold` × the 99th percentile of all peaks
   and the profile is narrow: fewer than `max_width` samples above half the peak. The second
   test drops the columns that the *other* stripe runs along (there the profile is bright
   over its whole length), which is where a per-column maximum would be meaningless.
"""

from __future__ import annotations

import numpy as np
from scipy import ndimage


def stripe_centres(
    image_rgb: np.ndarray,
    stripe: str,
    *,
    mask: np.ndarray | None = None,
    sigma: float = 1.5,
    rel_threshold: float = 0.2,
    max_width: int = 20,
) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Sub-pixel stripe centres of one RGB frame.

    Args:
        image_rgb: (H, W, 3) uint8 or float RGB.
        stripe: "h" (one centre per column) or "v" (one per row).
        mask: optional (H, W) bool; pixels outside are ignored.
        sigma: Gaussian smoothing, px.
        rel_threshold: minimum peak relative to the 99th percentile of peaks.
        max_width: maximum number of samples above half the peak.

    Returns:
        (pos, valid, strength): pos (W,) sub-pixel row per column for "h" ((H,) column per
        row for "v"), valid the kept centres, strength the peak value.
    """
    if stripe not in ("h", "v"):
        raise ValueError(f"stripe must be 'h' or 'v', got {stripe!r}")
    img = np.asarray(image_rgb, np.float64)
    if img.ndim != 3 or img.shape[2] != 3:
        raise ValueError(f"image must be (H, W, 3) RGB, got shape {img.shape}")
    im = np.clip(img[..., 0] - img[..., 1], 0, None)
    im = ndimage.gaussian_filter(im, sigma)
    if mask is not None:
        im = np.where(mask, im, 0.0)
    if stripe == "v":
        im = im.T  # rows of the transposed image are the columns of the original
    n = im.shape[0]
    k = np.argmax(im, axis=0)
    cols = np.arange(im.shape[1])
    peak = im[k, cols]
    km, kp = np.clip(k - 1, 0, n - 1), np.clip(k + 1, 0, n - 1)
    a, b, c = im[km, cols], peak, im[kp, cols]
    den = a - 2 * b + c
    off = np.where(den < 0, 0.5 * (a - c) / np.where(den < 0, den, -1.0), 0.0)
    pos = k + np.clip(off, -0.5, 0.5)
    width = np.sum(im > 0.5 * peak[None, :], axis=0)
    ref = np.percentile(peak, 99) if peak.size else 0.0
    valid = (peak > rel_threshold * ref) & (peak > 0) & (width <= max_width)
    valid &= (k > 0) & (k < n - 1)
    return pos, valid, peak
