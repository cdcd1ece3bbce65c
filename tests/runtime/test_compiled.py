"""`cslx.runtime.compiled`: an exported program reloaded gives jit's results."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from cslx.runtime.compiled import cached_program, compile_cached


class State(eqx.Module):
    a: jax.Array
    n: jax.Array


def test_reloaded_program_equals_jit_and_keys_separate(tmp_path):
    scale = jnp.asarray(3.0)

    def step(x, s: State):
        y = jnp.fft.rfft(x).real.sum() * scale + s.a
        return (y, x * 2), State(s.a + 1, s.n + 1)

    x = jnp.arange(8.0)
    s0 = State(jnp.asarray(0.5), jnp.asarray(0))
    out_like = ((0, 0), s0)
    spec = jax.ShapeDtypeStruct(x.shape, x.dtype)
    ref = jax.jit(step)(x, s0)
    first = compile_cached(step, (spec, s0), out_like, "k1", directory=tmp_path)
    files = list((tmp_path / "cslx-export").iterdir())
    assert len(files) == 1
    again = compile_cached(step, (spec, s0), out_like, "k1", directory=tmp_path)
    assert list((tmp_path / "cslx-export").iterdir()) == files  # reloaded, not re-exported
    for fn in (first, again):
        got = fn(x, s0)
        assert isinstance(got[1], State)
        for a, b in zip(
            jax.tree_util.tree_leaves(got), jax.tree_util.tree_leaves(ref), strict=True
        ):
            np.testing.assert_allclose(np.asarray(a), np.asarray(b))
    compile_cached(step, (spec, s0), out_like, "k2", directory=tmp_path)
    assert len(list((tmp_path / "cslx-export").iterdir())) == 2


def test_cached_program_reloads_without_build(tmp_path):
    """The second start gets program, example arguments and metadata from the file alone."""
    calls = []

    def build():
        calls.append(1)

        def fn(x, a, n):
            return jnp.cumsum(x) * a, n + 1

        spec = jax.ShapeDtypeStruct((5,), jnp.float32)
        return fn, (spec, jnp.asarray(2.5, jnp.float32), jnp.arange(3, dtype=jnp.int32)), {"f": [1]}

    first, args1, meta1 = cached_program("p", build, directory=tmp_path)
    again, args2, meta2 = cached_program("p", build, directory=tmp_path)
    assert len(calls) == 1 and meta1 == meta2 == {"f": [1]}
    assert isinstance(args2[0], jax.ShapeDtypeStruct) and args2[0].shape == (5,)
    x = jnp.arange(5.0, dtype=jnp.float32)
    for fn, args in ((first, args1), (again, args2)):
        y, n = fn(x, *args[1:])
        np.testing.assert_allclose(np.asarray(y), np.cumsum(np.arange(5.0)) * 2.5)
        np.testing.assert_array_equal(np.asarray(n), [1, 2, 3])
    cached_program("other", build, directory=tmp_path)
    assert len(calls) == 2
