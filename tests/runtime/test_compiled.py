"""`cslx.runtime.compiled.compile_cached`: an exported program reloaded gives jit's results."""

import equinox as eqx
import jax
import jax.numpy as jnp
import numpy as np

from cslx.runtime.compiled import compile_cached


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
