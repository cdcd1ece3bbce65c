"""The fused small kernels of the bead fits equal the library calls they replace."""

import jax
import jax.numpy as jnp
import numpy as np

from cslx.runtime.small_ops import masked_median, solve_spd


def test_masked_median_equals_nanmedian():
    rng = np.random.default_rng(5)
    f = jax.jit(masked_median)
    for t in range(120):
        n = int(rng.integers(1, 700))
        x = (rng.standard_normal(n) * 10 ** rng.uniform(-3, 3)).astype(np.float32)
        if t % 3 == 0:
            x = np.abs(x)
        if t % 4 == 0:
            x[:3] = 0.0  # ties and zeros
        if t % 7 == 0:
            x[rng.random(n) < 0.2] = np.nan
        m = rng.random(n) < rng.uniform(0, 1)
        ref = float(jnp.nanmedian(jnp.where(m, x, jnp.nan)))
        got = float(f(jnp.asarray(x), jnp.asarray(m)))
        if np.isnan(ref):
            assert np.isnan(got)
        else:
            assert abs(got - ref) <= 1e-6 * abs(ref), (t, ref, got)


def test_masked_median_other_dtypes_fall_back():
    x = jnp.asarray([3.0, 1.0, 2.0, 10.0], jnp.float16)
    assert float(masked_median(x, jnp.asarray([True, True, True, False]))) == 2.0


def test_solve_spd_equals_linalg_solve():
    rng = np.random.default_rng(6)
    for n in (2, 3, 4):
        A = rng.standard_normal((40, n)).astype(np.float32)
        M, v = A.T @ A + 1e-6 * np.eye(n, dtype=np.float32), rng.standard_normal(n)
        np.testing.assert_allclose(
            np.asarray(solve_spd(jnp.asarray(M), jnp.asarray(v, jnp.float32))),
            np.linalg.solve(M.astype(np.float64), v),
            rtol=1e-4,
            atol=1e-6,
        )
