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
