"""Second pass of the linked detector: re-measure each centre along the found path.

The linked detector (`cslx.segmentation.ridges`) must smooth the image along the stripe
(`robust.SIGMA_ALONG`, 6 px along the image axis) to find the weak and sunlit stretches at
all; that smoothing averages neighbouring columns whose stripe lies at other rows wherever
the path curves, and rounds the bead's corners before any centre is measured. Once the path
is known, which ridge is the laser is decided, and each column can be measured again:

1. For every column j of the path (row for the vertical stripe) the monochrome profile is
   convolved with Gaussian derivatives of scale σ across the stripe, evaluated at the
   sub-pixel offsets y = p_j + δ (|δ| ≤ `REACH` px, step `STEP`) from the first pass's
   (smoothed) path p_j: s′(y) = Σ_i f(i) g′(y − i). The kernels are evaluated at the
   continuous offsets, so there is no interpolation.
2. Optionally s′ is averaged over neighbouring path columns at the same offset δ
   (`sigma_along` px, a Gaussian normalised over the valid ones): smoothing along the *path*,
   not the image axis, so a curved or cornered stripe is not bent towards its chord — only
   the first pass's own error p − true enters, and that only through its curvature.
3. The centre is the zero crossing of s′ (s′ > 0 before it, ≤ 0 after) nearest δ = 0,
   linearly interpolated between offsets (Steger 1998 eq. (17) in 1-D: the maximum of the
   smoothed profile along the column). Where there is none within the reach the first
   pass's centre is kept.

Pure JAX, jit- and vmap-able.
"""

from __future__ import annotations

import functools
import math

import jax
import jax.numpy as jnp
import numpy as np

__all__ = ["REACH", "STEP", "refine_centres"]

#: Largest distance (px) of the re-measured centre from the first pass's path.
REACH = 2.0
#: Spacing (px) of the offsets at which the profile's derivative is evaluated.
STEP = 0.25


@functools.partial(jax.jit, static_argnames=("sigma", "sigma_along", "axis"))
def refine_centres(mono, pos, valid, *, sigma: float, sigma_along: float, axis: int):
    """Centres re-measured around the path `pos` (module docstring).

    Args:
        mono: (H, W) monochrome image, bright stripe.
        pos, valid: (N,) first-pass centres along the search axis and their mask.
        sigma: Gaussian scale across the stripe (px, static).
        sigma_along: smoothing along the path (px, static; 0: none).
        axis: 0 horizontal stripe (one centre per column), 1 vertical.

    Returns:
        (pos, found): the re-measured centres (the first pass's where nothing was found or
        not valid) and the mask of centres that were re-measured.
    """
    x = mono.T if axis == 0 else mono  # (N, M): one row per path column
    n, m = x.shape
    dtype = x.dtype
    p = jnp.where(valid, jnp.nan_to_num(pos), 0.0)
    half = int(math.ceil(REACH + 4 * sigma))
    base = jnp.round(p).astype(jnp.int32)
    taps = jnp.arange(-half, half + 1)
    idx = jnp.clip(base[:, None] + taps[None, :], 0, m - 1)
    f = jnp.take_along_axis(x, idx, 1)  # (N, T)
    f = f - jnp.mean(f, axis=1, keepdims=True)
    k = int(round(REACH / STEP))
    delta = jnp.asarray(np.arange(-k, k + 1) * STEP, dtype)
    # u = y − i for y = p + δ and the tapped rows i = base + taps.
    u = (p - base)[:, None, None] + delta[None, :, None] - taps[None, None, :].astype(dtype)
    g = jnp.exp(-0.5 * (u / sigma) ** 2)
    s1 = jnp.einsum("nt,nkt->nk", f, -u / sigma**2 * g)  # s′(p + δ), up to a constant
    w = valid.astype(dtype)
    if sigma_along > 0:
        r = int(math.ceil(3 * sigma_along))
        kern = np.exp(-0.5 * (np.arange(-r, r + 1) / sigma_along) ** 2)
        kern = jnp.asarray(kern / kern.sum(), dtype)

        def along(a):
            return jax.vmap(lambda c: jnp.convolve(c, kern, mode="same"), 1, 1)(a)

        norm = jnp.convolve(w, kern, mode="same")
        s1 = along(s1 * w[:, None]) / jnp.maximum(norm, 1e-6)[:, None]
    a, b = s1[:, :-1], s1[:, 1:]
    cross = (a > 0) & (b <= 0)
    frac = a / jnp.where(cross, a - b, 1.0)
    where = delta[:-1][None, :] + STEP * frac  # (N, 2k)
    dist = jnp.where(cross, jnp.abs(where), jnp.inf)
    best = jnp.argmin(dist, axis=1)
    found = valid & jnp.isfinite(jnp.min(dist, axis=1))
    new = p + jnp.take_along_axis(where, best[:, None], 1)[:, 0]
    return jnp.where(found, new, pos), found
