"""The fused small kernels of the bead fits equal the library calls they replace."""

import jax
import jax.numpy as jnp
import numpy as np

from cslx.runtime.small_ops import masked_median, one_function, solve_spd, window_nanmedian


def test_masked_median_equals_nanmedian():
    """Against NumPy's nanmedian over 120 random lengths, each padded with masked-out points
    to one of three sizes (the padding's values must not count; three compiles, not 120)."""
    rng = np.random.default_rng(5)
    f = jax.jit(masked_median)
    for t in range(120):
        n = int(rng.integers(1, 700))
        x = (rng.standard_normal(n) * 10 ** rng.uniform(-3, 3)).astype(np.float32)
        if t % 3 == 0:
            x = np.abs(x)
        if t % 4 == 0:
            x[:3] = 0.0  # ties and zeros
        if t % 5 == 0:
            x = np.round(x, 1)  # many ties at the middle ranks
        if t % 7 == 0:
            x[rng.random(n) < 0.2] = np.nan
        m = rng.random(n) < rng.uniform(0, 1)
        chosen = np.where(m, x, np.nan)
        ref = float(np.nanmedian(chosen)) if not np.all(np.isnan(chosen)) else np.nan
        pad = next(size for size in (64, 256, 704) if size >= n) - n
        xp = np.concatenate([x, (rng.standard_normal(pad) * 1e3).astype(np.float32)])
        mp = np.concatenate([m, np.zeros(pad, bool)])
        got = float(f(jnp.asarray(xp), jnp.asarray(mp)))
        if np.isnan(ref):
            assert np.isnan(got)
        else:
            assert abs(got - ref) <= 1e-6 * abs(ref), (t, ref, got)


def test_masked_median_bracket_edge_cases_bit_for_bit():
    """The bracketed bisection stops when one point is left in its bracket, or runs down to a
    single key (a repeated middle value): against `jnp.nanmedian` bit for bit, batched with
    `vmap` (the loop's stopping test is then per row), on ties, a single point, no point,
    infinities, signed zeros, subnormals and values spread over many octaves."""
    rng = np.random.default_rng(13)
    n = 96
    rows, masks = [], []
    for t in range(64):
        x = (rng.standard_normal(n) * 10 ** rng.uniform(-30, 30, n)).astype(np.float32)
        kind = t % 8
        if kind == 1:
            x = np.round(rng.standard_normal(n)).astype(np.float32)  # few distinct values
        if kind == 2:
            x[:] = 7.0  # one value
        if kind == 3:
            x[rng.random(n) < 0.3] = np.inf
            x[rng.random(n) < 0.3] = -np.inf
        if kind == 4:
            x = np.where(rng.random(n) < 0.5, np.float32(0.0), np.float32(-0.0))
            x[::7] = np.float32(1e-40)  # subnormal
        if kind == 5:
            x[rng.random(n) < 0.5] = np.nan
        m = rng.random(n) < (0.0, 1.0 / n, 2.0 / n, 0.5, 1.0)[t % 5]
        if t % 5 == 1:
            m[rng.integers(n)] = True  # exactly one point (or two)
        rows.append(x)
        masks.append(m)
    x, m = jnp.asarray(np.stack(rows)), jnp.asarray(np.stack(masks))
    got = np.asarray(jax.jit(jax.vmap(masked_median))(x, m))
    ref = np.asarray(jax.vmap(lambda a, b: jnp.nanmedian(jnp.where(b, a, jnp.nan)))(x, m))
    np.testing.assert_array_equal(got, ref)
    assert np.isnan(got[np.asarray(m).sum(1) == 0]).all()


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


def test_window_nanmedian_equals_sorted_windows():
    """Bit for bit `jnp.nanmedian` over the (n, 2k+1) windows of the profile clean-up."""
    rng = np.random.default_rng(11)
    f = jax.jit(window_nanmedian, static_argnums=1)
    for t in range(16):
        k = (0, 1, 4)[t % 3]
        n = (1, 5, 480, 640)[t % 4]  # few shapes: one compile each
        z = rng.standard_normal(n) * 10 ** rng.uniform(-3, 3)
        if t % 3 == 0:
            z = np.round(z)  # ties
        z[rng.random(n) < rng.uniform(0, 1)] = np.nan
        if t % 4 == 0:
            z[: n // 3] = np.nan  # windows without any number
        z = jnp.asarray(z.astype(np.float32))
        windows = jnp.stack(
            [jnp.pad(z, (k, k), constant_values=jnp.nan)[j : j + n] for j in range(2 * k + 1)],
            axis=1,
        )
        ref = np.asarray(jnp.nanmedian(windows, axis=1))
        got = np.asarray(f(z, k))
        assert got.dtype == ref.dtype
        np.testing.assert_array_equal(got, ref, err_msg=f"trial {t}, k={k}")


def test_one_function_equals_the_call():
    """A pytree of results of a function with loops and reductions, bit for bit, also for
    a NaN in the probed entry and under vmap (the loop's condition is then batched)."""

    def f(x, w):
        c = jax.lax.fori_loop(0, 5, lambda i, c: c + jnp.sum(w * jnp.cos(x * c)), 0.5)
        return {"c": c, "m": masked_median(x, w > 0.5), "y": jnp.cumsum(x * w)[::7]}

    rng = np.random.default_rng(8)
    run, ref = jax.jit(lambda x, w: one_function(f, x, w)), jax.jit(f)
    for k in range(6):
        x = rng.standard_normal(300).astype(np.float32)
        if k == 1:
            x[0] = np.nan
        w = rng.random(300).astype(np.float32)
        for a, b in zip(jax.tree.leaves(run(x, w)), jax.tree.leaves(ref(x, w)), strict=True):
            np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
    X, W = rng.standard_normal((3, 50)).astype(np.float32), rng.random((3, 50)).astype(np.float32)
    got = jax.vmap(lambda x, w: one_function(f, x, w))(X, W)
    want = jax.vmap(f)(X, W)
    for a, b in zip(jax.tree.leaves(got), jax.tree.leaves(want), strict=True):
        np.testing.assert_array_equal(np.asarray(a), np.asarray(b))
