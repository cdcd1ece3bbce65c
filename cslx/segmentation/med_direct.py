"""Linear-phase MED on short bands by direct convolutions (tracking mode, issue 13).

The same fixed point as `cslx.segmentation.med.med` with ``symmetric=True`` and
``delay="centre"`` (eqs. (22)–(24) restricted to W_k = W_{L−1−k}, correction 5), with the
same centring and taper of the segments, the same diagonal loading and the same stopping
rule (relative change of Σ_j k_j below ``tol``, Table 2 step 5), but the iteration's
correlations are short direct sums instead of FFTs: a band filter has L = 16 taps, so

- the output B = W ∗ X (eq. (21)) is L shifted multiply-adds per sample,
- b_k = Σ_j U_j⁻² Σ_i (B_ij − μ_j)³ X_{i−k,j} (eq. (22), right) is L shifted products,
- the autocorrelation r(τ) = Σ_i X_ij X_{i+τ,j} of R (eq. (22), left) does not depend on W
  and is computed once per frame; each step only weights it by k_j / U_j.

Only the delay-compensated output (a shift by (L − 1)/2, a half sample for even L) still
goes through one FFT pair (`med_fft.shifted_output`). All sums run over the full
convolution length m + L − 1, exactly the terms of the FFT form (no wrap-around), so the
two agree to float rounding (tests/segmentation/test_med_direct.py).
"""

from __future__ import annotations

import jax.numpy as jnp
import jax.scipy.linalg as jsl
from jax import lax
from jaxtyping import Array, Float

from . import med_fft as _f
from .med import DEFAULT_TAPER, MEDResult, _check_image, _default_loading, _length, stripe_segments

__all__ = ["med_band"]


def _full_conv(X, W):
    """(s, m + L − 1) full convolution of every segment with W."""
    L = W.shape[0]
    # B_i = Σ_k W_k X_{i−k}: a cross-correlation with the reversed filter (XLA's conv)
    out = lax.conv_general_dilated(
        X[:, None, :], W[::-1][None, None, :], (1,), [(L - 1, L - 1)],
        dimension_numbers=("NCH", "OIH", "NCH"),
    )  # fmt: skip
    return out[:, 0, :]


def _stats(W, X):
    """Σ_j k_j, excess kurtosis, weights w = k/U, v = 1/U², centred output b (`med_fft.stats`)."""
    m, L = X.shape[1], W.shape[0]
    B = _full_conv(X, W)
    b = B - jnp.mean(B, axis=1, keepdims=True)
    b2 = b * b
    U = jnp.sum(b2, axis=1)
    F = jnp.sum(b2 * b2, axis=1)
    ok = U > jnp.finfo(U.dtype).eps * jnp.max(U)
    Us = jnp.where(ok, U, 1.0)
    k = jnp.where(ok, F / (Us * Us), 0.0)
    n_ok = jnp.maximum(jnp.sum(ok), 1)
    excess = jnp.sum(jnp.where(ok, (m + L - 1) * k - 3.0, 0.0)) / n_ok
    return jnp.sum(k), excess, jnp.where(ok, k / Us, 0.0), jnp.where(ok, 1 / (Us * Us), 0.0), b


def _autocorrelation(X, L: int):
    """(s, L) r_j(τ) = Σ_i X_ij X_{i+τ,j}, τ = 0..L−1 (once per frame)."""
    m = X.shape[1]
    Xp = jnp.pad(X, ((0, 0), (0, L - 1)))
    return jnp.stack([jnp.sum(X * lax.slice_in_dim(Xp, t, t + m, axis=1), axis=1) for t in range(L)], 1)


def _toeplitz(r):
    L = r.shape[0]
    idx = jnp.abs(jnp.arange(L)[:, None] - jnp.arange(L)[None, :])
    return r[idx]


def _update(W, X, A, P, loading):
    """One linear-phase fixed-point step (`med_fft.update` with ``symmetric``)."""
    L = W.shape[0]
    m = X.shape[1]
    rs, excess, w, v, b = _stats(W, X)
    c = b * b * b
    # b_k = Σ_j v_j Σ_i c_{i+k, j} X_{i, j}
    cv = c * v[:, None]
    bvec = lax.conv_general_dilated(
        cv[None], X[None], (1,), [(0, 0)], dimension_numbers=("NCH", "OIH", "NCH")
    )[0, 0]  # fmt: skip
    r = w @ A
    R = _toeplitz(r) + (loading * r[0]) * jnp.eye(L, dtype=r.dtype)
    h = jsl.cho_solve(jsl.cho_factor(P.T @ R @ P, lower=True), P.T @ bvec)
    x = P @ h
    return x / jnp.linalg.norm(x), rs


def med_band(
    I: Float[Array, "h w"],
    W0: Float[Array, " L"],
    *,
    axis: int = 0,
    tol: float = 1e-4,
    max_steps: int = 2,
    taper: int = DEFAULT_TAPER,
    loading: float | None = None,
) -> MEDResult:
    """Linear-phase MED of a band from the filter ``W0`` (module notes), jit-traceable.

    Equals `cslx.segmentation.med.med` (``symmetric=True``, ``init=W0``, ``L=len(W0)``,
    delay "centre") to float rounding. Meant for short filters: the direct sums cost
    O(L·s·m) per step against the FFT form's O(s·n log n).
    """
    I = _check_image(I)
    L = _length(I, axis, W0.shape[0])
    dtype = I.dtype
    loading = _default_loading(dtype) if loading is None else float(loading)
    X = _f.centre_and_taper(stripe_segments(I, axis), taper)
    A = _autocorrelation(X, L)
    P = jnp.asarray(_f.symmetric_basis(L), dtype)
    W0 = jnp.asarray(W0, dtype)
    W0 = W0 / jnp.linalg.norm(W0)
    atol = tol * 1e-6

    # optimistix.FixedPointIteration on y = (W, Σ_j k_j of the previous W), norm = the
    # change of the second component relative to atol + tol·|new value| (`med._med`).
    def cond(carry):
        _, _, steps, err = carry
        return (err >= 1) & (steps < max_steps)

    def body(carry):
        W, rs_prev, steps, _ = carry
        W_new, rs = _update(W, X, A, P, loading)
        err = jnp.abs(rs_prev - rs) / (atol + tol * jnp.abs(rs))
        return W_new, rs, steps + 1, err

    init = (W0, jnp.zeros((), dtype), jnp.zeros((), jnp.int32), jnp.asarray(jnp.inf, dtype))
    W, _, steps, err = lax.while_loop(cond, body, init)
    _, excess, w, _, _ = _stats(W, X)
    c = _toeplitz(w @ A) @ W  # output/input correlation c(t) = Σ_k W_k r(t − k)
    sign = jnp.where(c[(L - 1) // 2] + c[L // 2] < 0, -1.0, 1.0).astype(dtype)
    W = W * sign
    delay = jnp.asarray((L - 1) / 2, dtype)
    out = _f.shifted_output(W, delay, _f.prepare(X, L))
    out = out.T if axis == 0 else out
    return MEDResult(out, W, delay, excess, steps, err < 1)
