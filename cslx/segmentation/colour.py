"""Monochromatic value space chosen by kurtosis (section 3.1 of the paper).

An RGB frame becomes one channel by the linear map of eq. (8),

    I_ij = w_r R_ij + w_g G_ij + w_b B_ij,

and the weights are chosen to make the stripe as "spiky" as possible: the laser
concentrates its energy in a few rows of each column, sunlight is nearly grey (R ≈ G ≈ B)
and spread out. The paper scores a space by the kurtosis of its columns, eqs. (9)–(12),

    K² = ( Σ_j Σ_i (I_ij − μ_j)⁴ / (Σ_i (I_ij − μ_j)²)² − 3 )²            (12)

and searches the integer grid w_r ∈ {0, 1, 2}, w_g, w_b ∈ {−2..2}, not all zero (74 spaces).

Correction 4 (docs/corrections.md): the printed per-column ratio lacks the factor M of the sample
kurtosis, and its "−3" is applied once to the sum over N columns instead of to each column.
Both forms are offered:

- ``"paper"``: the literal eq. (12), (Σ_j k_j − 3)² with k_j = Σ(I−μ)⁴ / (Σ(I−μ)²)².
- ``"normalized"``: the mean over columns of the sample excess kurtosis, M k_j − 3.

Both are monotone in S = Σ_j k_j while S > 3, so they rank spaces identically on every
frame with a clear stripe in it (S ≈ 3N/M for Gaussian noise, 4 on a 640×480 frame scored
by columns, and grows with the stripe). They part where S < 3: the square turns the
literal form around, so a *flat*, low-kurtosis space (k_j → 1/M) can outscore a weak
stripe. Scored by rows (the vertical stripe, N/M = 480/640) pure noise already has
S ≈ 2.25 < 3. The normalized form has no reversal, reads as a kurtosis (0 for Gaussian
noise) and does not grow with N/M: it is the default. Evidence (rendered cross scenes,
`cslx.sim`, sunny/shadow/glare, laser power 260/60/25/12/6, 3 frames each, both stripe
directions, 90 searches): the forms chose the same space 82 times; the 8 differences were
all weak-stripe row-wise searches, and the normalized choice put the per-row maximum within
2 px of the true stripe more often in 7 of the 8 (e.g. power 25: 46 % vs 39 % of rows;
one paper-form pick, (−2, −1, 1), hid the stripe completely).

Kurtosis is even in the weights and scale-invariant: w, 2w and −w score the same. The
search therefore returns the sign that makes the stripe bright (positive skewness), so a
green laser gives G − R or 2G − R − B rather than the grid's R − G with a dark stripe.

Clipped cores. When the laser core saturates to white (R = G = B = 255), every zero-sum
space (R − G, 2R − G − B, …) maps the core to 0: the stripe becomes two thin lobes around
a hole. The search does not notice: thin lobes are as impulsive as an intact peak, so on
rendered frames with clipped cores (power 260–800) it still picks R − G / 2R − G − B (or
2G − R − B for green), while the per-column maximum lands on a lobe, > 2 px from the
true centre in 30–95 % of columns (gray keeps the core: 80–90 % within 2 px, but passes
the sunlight). Filling white pixels with the space's maximum was tried and rejected: it
also fills white glints (glare scenes: 90 % → 64 % within 2 px). The centre detector must
therefore cope with a split core (smoothing wider than the hole merges the lobes).

Everything is pure JAX, differentiable in the weights and the image, jit/vmap friendly;
the dtype follows the inputs (uint8 frames become the default float dtype).
"""

from __future__ import annotations

import functools
from typing import Literal

import jax
import jax.numpy as jnp
import numpy as np
from jaxtyping import Array, ArrayLike, Float

from ..config import COLOUR_GRID

__all__ = [
    "CANDIDATES",
    "NAMED_SPACES",
    "DEFAULT_FORM",
    "monochrome",
    "column_kurtosis",
    "kurtosis_objective",
    "search_space",
    "optimise_weights",
    "parse_space",
]

Form = Literal["normalized", "paper"]
DEFAULT_FORM: Form = "normalized"

# The paper's grid (section 3.1, correction 8): w_r ∈ {0,1,2}, w_g, w_b ∈ {−2..2}, ≠ 0.
CANDIDATES: np.ndarray = np.array(COLOUR_GRID, dtype=np.int32)
assert CANDIDATES.shape == (74, 3)

NAMED_SPACES: dict[str, tuple[float, float, float]] = {
    "r": (1.0, 0.0, 0.0),
    "g": (0.0, 1.0, 0.0),
    "b": (0.0, 0.0, 1.0),
    "r-g": (1.0, -1.0, 0.0),
    "g-r": (-1.0, 1.0, 0.0),
    "r-b": (1.0, 0.0, -1.0),
    "g-b": (0.0, 1.0, -1.0),
    "2r-g-b": (2.0, -1.0, -1.0),
    "2g-r-b": (-1.0, 2.0, -1.0),
    # ITU-R BT.601 luma; the paper rounds it to (0.30, 0.59, 0.11).
    "gray": (0.299, 0.587, 0.114),
}


def _float_image(image: ArrayLike) -> Array:
    image = jnp.asarray(image)
    if image.ndim != 3 or image.shape[-1] != 3:
        raise ValueError(f"expected an RGB image of shape (H, W, 3), got shape {image.shape}")
    if not jnp.issubdtype(image.dtype, jnp.floating):
        image = image.astype(jnp.result_type(float))
    return image


def monochrome(image: ArrayLike, weights: ArrayLike) -> Float[Array, "h w"]:
    """Monochromatic value image I = w_r R + w_g G + w_b B (eq. (8)).

    Args:
        image: (H, W, 3) RGB frame, uint8 (0..255) or float (any scale); channel order RGB.
        weights: (3,) weights (w_r, w_g, w_b).

    Returns:
        (H, W) float image in the image's float dtype (uint8 → the default float dtype).
    """
    image = _float_image(image)
    weights = jnp.asarray(weights)
    if weights.shape != (3,):
        raise ValueError(f"weights must have shape (3,), got {weights.shape}")
    dtype = jnp.result_type(image.dtype, weights.dtype)
    if not jnp.issubdtype(dtype, jnp.floating):
        dtype = jnp.result_type(float)
    return image.astype(dtype) @ weights.astype(dtype)


def _check_form(form: str) -> None:
    if form not in ("normalized", "paper"):
        raise ValueError(f"form must be 'normalized' or 'paper', got {form!r}")


def column_kurtosis(I: Float[Array, "m n"], form: Form = DEFAULT_FORM) -> Float[Array, " n"]:
    """Kurtosis of every column of a monochrome image (eqs. (9), (12), (24)).

    Args:
        I: (M, N) image; each column is one segment of M samples.
        form: ``"paper"`` gives the printed ratio k_j = Σ(I−μ)⁴ / (Σ(I−μ)²)² (eq. (24));
            ``"normalized"`` the sample excess kurtosis M k_j − 3 (correction 4).

    Returns:
        (N,) per-column values. A constant column (zero variance) carries no information
        and gets the neutral value: 0 (normalized) or 3/M, the Gaussian value (paper).
    """
    _check_form(form)
    I = jnp.asarray(I)
    m = I.shape[0]
    d = I - jnp.mean(I, axis=0, keepdims=True)
    d2 = d * d
    u = jnp.sum(d2, axis=0)
    f = jnp.sum(d2 * d2, axis=0)
    # Safe where: the ratio (and its gradient) of a flat column must not be NaN.
    tiny = jnp.finfo(u.dtype).tiny ** 0.25
    ok = u > tiny * jnp.maximum(jnp.max(u), tiny)
    u_safe = jnp.where(ok, u, 1.0)
    k = jnp.where(ok, f / (u_safe * u_safe), 3.0 / m)
    return m * k - 3.0 if form == "normalized" else k


def kurtosis_objective(
    weights: ArrayLike, image: ArrayLike, form: Form = DEFAULT_FORM, axis: int = 0
) -> Float[Array, ""]:
    """Kurtosis score of the colour space ``weights`` on an RGB frame (eqs. (8)–(12)).

    Args:
        weights: (3,) colour weights; the score is even and scale-invariant in them.
        image: (H, W, 3) RGB frame.
        form: ``"normalized"`` (default): mean over segments of the sample excess kurtosis;
            ``"paper"``: the literal eq. (12), (Σ_j k_j − 3)². See the module docstring.
        axis: 0 scores columns (horizontal stripe, as the paper), 1 scores rows.

    Returns:
        Scalar score, larger is better; differentiable in ``weights`` and ``image``.
    """
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (columns) or 1 (rows), got {axis}")
    I = monochrome(image, weights)
    if axis == 1:
        I = I.T
    k = column_kurtosis(I, form)
    return jnp.mean(k) if form == "normalized" else (jnp.sum(k) - 3.0) ** 2


def _skewness_sign(weights: Array, image: Array, axis: int) -> Array:
    """+1 when the space makes the stripe bright (positive third moment summed over segments)."""
    I = monochrome(image, weights)
    if axis == 1:
        I = I.T
    d = I - jnp.mean(I, axis=0, keepdims=True)
    u = jnp.sum(d * d, axis=0)
    ok = u > 0
    skew = jnp.where(ok, jnp.sum(d**3, axis=0) / jnp.where(ok, u, 1.0) ** 1.5, 0.0)
    return jnp.where(jnp.sum(skew) < 0, -1.0, 1.0).astype(weights.dtype)


@functools.partial(jax.jit, static_argnames=("form", "axis"))
def _search(image, candidates, form, axis):
    w = candidates.astype(image.dtype)
    scores = jax.vmap(lambda wk: kurtosis_objective(wk, image, form, axis))(w)
    best = w[jnp.argmax(scores)]
    return best * _skewness_sign(best, image, axis), scores


def search_space(
    image: ArrayLike,
    form: Form = DEFAULT_FORM,
    candidates: ArrayLike = CANDIDATES,
    axis: int = 0,
) -> tuple[Float[Array, 3], Float[Array, " k"]]:
    """Exhaustive search of the paper's integer colour spaces, in one vectorised call (§3.1).

    Args:
        image: (H, W, 3) RGB frame.
        form: kurtosis form, see `kurtosis_objective`.
        candidates: (K, 3) weights to score, default the paper's 74-space grid `CANDIDATES`.
        axis: 0 scores columns (horizontal stripe), 1 rows (vertical stripe).

    Returns:
        best_weights (3,): the highest-scoring candidate (first on ties), its sign flipped if
        needed so that the stripe is bright (e.g. (−1, 1, 0) = G − R for a green laser);
        scores (K,): every candidate's score.
    """
    _check_form(form)
    if axis not in (0, 1):
        raise ValueError(f"axis must be 0 (columns) or 1 (rows), got {axis}")
    image = _float_image(image)
    candidates = jnp.asarray(candidates)
    if candidates.ndim != 2 or candidates.shape[1] != 3:
        raise ValueError(f"candidates must have shape (K, 3), got {candidates.shape}")
    return _search(image, candidates, form, axis)


@functools.partial(jax.jit, static_argnames=("form", "axis", "max_steps"))
def _optimise(image, init, form, axis, rtol, atol, max_steps):
    scale = jnp.linalg.norm(init)

    def loss(w, image):
        # Kurtosis is scale-invariant, so the unconstrained problem has the sphere's
        # optima along rays; normalising inside keeps BFGS well-scaled.
        return -kurtosis_objective(w / jnp.linalg.norm(w), image, form, axis)

    import optimistix as optx  # lazy: importing cslx.runtime does not need it

    solver = optx.BFGS(rtol=rtol, atol=atol)
    sol = optx.minimise(loss, solver, init / scale, args=image, max_steps=max_steps, throw=False)
    w = sol.value / jnp.linalg.norm(sol.value)
    # Never return something worse than the start (BFGS may stop on a failed line search).
    w0 = init / scale
    better = loss(w, image) <= loss(w0, image)
    w = jnp.where(better, w, w0)
    w = w * _skewness_sign(w, image, axis)
    return w, -loss(w, image), sol.stats["num_steps"], sol.result == optx.RESULTS.successful


def optimise_weights(
    image: ArrayLike,
    init: ArrayLike | None = None,
    *,
    form: Form = DEFAULT_FORM,
    axis: int = 0,
    rtol: float = 1e-6,
    atol: float = 1e-8,
    max_steps: int = 100,
) -> Float[Array, 3]:
    """Continuous colour space on the unit sphere maximising kurtosis (correction 8).

    Gradient-based ascent (optimistix BFGS with line search) of `kurtosis_objective` over
    w/‖w‖, starting from ``init`` or, by default, from the best integer candidate of
    `search_space`, so the result scores at least as high as the grid's best.

    Args:
        image: (H, W, 3) RGB frame.
        init: (3,) starting weights (any scale), default the grid's best.
        form, axis: as in `kurtosis_objective`.
        rtol, atol, max_steps: BFGS stopping rule.

    Returns:
        (3,) unit weights with the stripe bright (positive skewness).
    """
    _check_form(form)
    image = _float_image(image)
    if init is None:
        init, _ = search_space(image, form=form, axis=axis)
    init = jnp.asarray(init, dtype=image.dtype)
    if init.shape != (3,) or not bool(jnp.any(init != 0)):
        raise ValueError(f"init must be three weights, not all zero; got {init}")
    w, _, _, _ = _optimise(image, init, form, axis, rtol, atol, max_steps)
    return w


def parse_space(text: str) -> tuple[float, float, float] | Literal["auto"]:
    """Parse a ``--space`` argument: a name of `NAMED_SPACES`, ``"auto"``, or ``"W_R,W_G,W_B"``.

    Returns:
        The (w_r, w_g, w_b) weights, or the string ``"auto"`` (kurtosis search wanted).
    """
    key = text.strip().lower().replace(" ", "")
    if key == "auto":
        return "auto"
    if key in NAMED_SPACES:
        return NAMED_SPACES[key]
    parts = key.split(",")
    if len(parts) == 3:
        try:
            w = tuple(float(p) for p in parts)
        except ValueError:
            w = None
        if w is not None:
            if not all(np.isfinite(w)) or not any(w):
                raise ValueError(f"colour space {text!r}: weights must be finite, not all zero")
            return w  # type: ignore[return-value]
    names = ", ".join(sorted(NAMED_SPACES))
    raise ValueError(
        f"unknown colour space {text!r}: use one of {names}, 'auto', or three weights 'W_R,W_G,W_B'"
    )
