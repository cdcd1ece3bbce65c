"""MED's Toeplitz solve (Levinson's recursion, issue 13) and the known-delay output.

References: SciPy's `solve_toeplitz` and a dense Cholesky solve for R⁻¹b (eq. (22)), and
`med_apply` for `med_output`. float64 (conftest) unless a test says otherwise.
"""

from __future__ import annotations

import jax
import jax.numpy as jnp
import numpy as np
import pytest
from scipy.linalg import solve_toeplitz

from cslx.segmentation import med_fft
from cslx.segmentation.med import med_apply, med_output


def autocorrelation(L, seed, smooth=5):
    """First column of a positive definite Toeplitz R: the autocorrelation of smooth noise."""
    rng = np.random.default_rng(seed)
    x = np.convolve(rng.standard_normal(4 * L + 50), np.ones(smooth) / smooth, "valid")
    n = x.size
    return np.array([x[: n - k] @ x[k:] for k in range(L)]) * (1 + 1e-9 * (np.arange(L) == 0))


@pytest.mark.parametrize("L, seed", [(1, 0), (2, 1), (9, 2), (64, 3), (240, 4)])
def test_levinson_equals_scipy_solve_toeplitz(L, seed):
    r = autocorrelation(L, seed)
    b = np.random.default_rng(seed + 10).standard_normal(L)
    ref = solve_toeplitz(r, b)
    got = np.asarray(jax.jit(med_fft.levinson)(jnp.asarray(r), jnp.asarray(b)))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8 * np.abs(ref).max())


def test_toeplitz_solve_equals_cholesky_solve():
    """The platform switch (CPU: Levinson) solves the same system as the dense matrix."""
    r = autocorrelation(50, 7)
    b = np.random.default_rng(8).standard_normal(50)
    R = np.asarray(med_fft.toeplitz(jnp.asarray(r)))
    np.testing.assert_array_equal(R, R.T)
    np.testing.assert_allclose(R[3, 7], r[4])
    ref = np.linalg.solve(R, b)
    got = np.asarray(jax.jit(med_fft.toeplitz_solve)(jnp.asarray(r), jnp.asarray(b)))
    np.testing.assert_allclose(got, ref, rtol=0, atol=1e-8 * np.abs(ref).max())


def test_levinson_float32_as_accurate_as_cholesky():
    """float32 (the speed path) with MED's loading: the error against the float64 solution
    is no worse than the dense Cholesky's, on an ill-conditioned smooth autocorrelation."""
    L = 120
    r = autocorrelation(L, 9, smooth=15)
    r[0] *= 1 + 1e-5
    b = np.random.default_rng(12).standard_normal(L)
    ref = solve_toeplitz(r, b)
    r32, b32 = jnp.asarray(r, jnp.float32), jnp.asarray(b, jnp.float32)
    lev = np.asarray(med_fft.levinson(r32, b32), float)
    R = med_fft.toeplitz(r32)
    chol = np.asarray(jax.scipy.linalg.cho_solve(jax.scipy.linalg.cho_factor(R), b32), float)

    def err(x):
        return np.linalg.norm(x - ref) / np.linalg.norm(ref)

    assert err(lev) <= 2 * err(chol) + 1e-6


@pytest.mark.parametrize("axis", [0, 1])
def test_med_output_is_med_apply_at_its_delay(axis):
    rng = np.random.default_rng(4)
    h, w = (64, 40) if axis == 0 else (40, 64)
    rows = np.arange(64)[:, None]
    I = 80 * np.exp(-0.5 * ((rows - 30 - 3 * np.sin(np.arange(40) / 7)) / 1.8) ** 2)
    I = I + rng.normal(0, 1.0, I.shape) + 10
    I = jnp.asarray(I if axis == 0 else I.T)
    W = np.hanning(16) + 0.3 * rng.standard_normal(16)
    W = jnp.asarray(W / np.linalg.norm(W))
    out, delay, _ = med_apply(I, W, axis=axis)
    got = med_output(I, W, delay, axis=axis)
    assert got.shape == I.shape
    np.testing.assert_allclose(np.asarray(got), np.asarray(out), rtol=1e-10, atol=1e-9)


def dense_ridge_positions(Y, sigma):
    """The reference: s' and s'' filtered over the whole row (NumPy), read at the argmax."""
    Y = np.asarray(Y, float)
    n = Y.shape[-1]
    h = min(int(4.0 * sigma + 0.5), n - 1)
    o = np.arange(h + 1, dtype=float)
    g = np.exp(-0.5 * (o / sigma) ** 2)
    g /= g[0] + 2 * g[1:].sum()
    g1 = -o / sigma**2 * g
    g2 = (o**2 / sigma**4 - 1 / sigma**2) * g
    Yp = np.pad(Y, ((0, 0), (h, h)))
    d1 = sum(g1[j] * (Yp[:, h - j : h - j + n] - Yp[:, h + j : h + j + n]) for j in range(1, h + 1))
    d2 = g2[0] * Y + sum(
        g2[j] * (Yp[:, h - j : h - j + n] + Yp[:, h + j : h + j + n]) for j in range(1, h + 1)
    )
    rows = np.arange(Y.shape[0])
    k = np.argmax(Y, axis=-1)
    t = -d1[rows, k] / np.where(d2[rows, k] < 0, d2[rows, k], -1.0)
    k = np.clip(k + np.clip(np.round(t), -h, h).astype(int), 0, n - 1)
    t2 = d2[rows, k]
    t = -d1[rows, k] / np.where(t2 < 0, t2, -1.0)
    return k + t, (t2 < 0) & (np.abs(t) <= 0.6)


def test_ridge_positions_equal_the_dense_filtering():
    """`med_fft.ridge_positions` evaluates s', s'' only at the two samples it reads: the same
    positions as filtering whole rows, ridges near both ends and ties included."""
    rng = np.random.default_rng(21)
    n = 97
    i = np.arange(n)
    centres = np.concatenate([rng.uniform(0, n - 1, 40), [0.0, 1.3, n - 1.0, n - 2.4, 50.0]])
    Y = 50 * np.exp(-0.5 * ((i[None, :] - centres[:, None]) / 2.2) ** 2)
    Y += rng.normal(0, 2.0, Y.shape)
    Y[-1] = 0.0  # a constant row: the first sample, no ridge
    Y[-2, 30:33] = 80.0  # a tie: the first maximum
    ref, ok_ref = dense_ridge_positions(Y, 2.0)
    got, ok = jax.jit(med_fft.ridge_positions, static_argnums=1)(jnp.asarray(Y), 2.0)
    np.testing.assert_array_equal(np.asarray(ok), ok_ref)
    np.testing.assert_allclose(np.asarray(got)[ok_ref], ref[ok_ref], rtol=0, atol=1e-9)
    assert ok_ref.sum() > 30
