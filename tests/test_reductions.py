"""`cslx.reductions.first_argmax`: ``jnp.argmax``'s answer from one integer max reduction."""

import jax
import jax.numpy as jnp
import numpy as np
import pytest

from cslx.reductions import first_argmax, ordered_int


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
def test_ordered_int_keeps_the_order_of_the_floats(dtype):
    x = np.array([-np.inf, -3.5, -1e-30, -0.0, 0.0, 1e-30, 2.0, 2.0000002, np.inf], dtype)
    o = np.asarray(ordered_int(jnp.asarray(x)))
    assert np.all(np.diff(o) > 0)
    assert np.asarray(ordered_int(jnp.asarray(np.array([np.nan], dtype))))[0] > o[-1]


@pytest.mark.parametrize("dtype", [np.float32, np.float64])
@pytest.mark.parametrize("axis", [0, 1])
def test_first_argmax_is_argmax_with_ties_infinities_and_nan(dtype, axis):
    rng = np.random.default_rng(3)
    a = np.round(rng.normal(size=(64, 50)), 1).astype(dtype)  # many exact ties
    a[rng.random(a.shape) < 0.3] = -np.inf
    a[4, :] = -np.inf
    a[:, 4] = -np.inf
    a[7, [5, 20]] = np.nan
    a[[9, 30], 8] = np.nan
    got, found = first_argmax(jnp.asarray(a), axis)
    np.testing.assert_array_equal(np.asarray(got), np.argmax(a, axis=axis))
    assert np.asarray(found).all()
    # distinct random values: the exact maximum, also in float32
    b = rng.normal(size=(64, 50)).astype(dtype)
    got, _ = first_argmax(jnp.asarray(b), axis)
    np.testing.assert_array_equal(np.asarray(got), np.argmax(b, axis))


def test_where_excludes_entries_and_reports_empty_lines():
    x = jnp.asarray([[5.0, 1.0, 3.0], [2.0, 9.0, 9.0], [7.0, 8.0, 0.5]])
    where = jnp.asarray([[False, True, True], [True, True, True], [False, False, False]])
    idx, found = first_argmax(x, 1, where)
    np.testing.assert_array_equal(np.asarray(idx), [2, 1, 0])
    np.testing.assert_array_equal(np.asarray(found), [True, True, False])


def test_jit_vmap_and_no_gradient_through_the_index():
    x = jnp.asarray(np.random.default_rng(1).normal(size=(3, 7, 11)))
    idx = jax.jit(jax.vmap(lambda a: first_argmax(a, 0)[0]))(x)
    np.testing.assert_array_equal(np.asarray(idx), np.argmax(np.asarray(x), axis=1))

    def f(a):  # a value read at the index: the gradient reaches only that entry
        i, _ = first_argmax(a)
        return jnp.sum(a[jnp.arange(a.shape[0]), i])

    g = np.asarray(jax.grad(f)(x[0]))
    expected = np.zeros_like(g)
    expected[np.arange(7), np.argmax(np.asarray(x[0]), axis=1)] = 1.0
    np.testing.assert_array_equal(g, expected)
