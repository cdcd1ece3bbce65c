"""`cslx.runtime.compiled`: an exported program reloaded gives jit's results."""

import pathlib
import subprocess
import sys

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


def _cumsum_build():
    def fn(x, a):
        return (jnp.cumsum(x) * a,)

    spec = jax.ShapeDtypeStruct((6,), jnp.float32)
    return fn, (spec, jnp.asarray(1.5, jnp.float32)), {}


def test_program_in_jax_cache_is_still_saved_runnable(tmp_path):
    """The file holds a freshly compiled executable even when JAX's persistent cache already
    has the program (one read back from that cache serialises without its machine code and
    fails when run: "Function … not found")."""
    from jax.experimental.compilation_cache import compilation_cache

    old = (
        jax.config.jax_compilation_cache_dir,
        jax.config.jax_persistent_cache_min_compile_time_secs,
    )
    compilation_cache.reset_cache()
    jax.config.update("jax_compilation_cache_dir", str(tmp_path / "xla"))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", 0.0)
    try:
        fn, args, _ = _cumsum_build()
        jax.jit(fn).lower(*args).compile()  # now in JAX's persistent cache
        assert list((tmp_path / "xla").iterdir())
        cached_program("c", _cumsum_build, directory=tmp_path / "prog")
        again, args2, _ = cached_program("c", lambda: 1 / 0, directory=tmp_path / "prog")
        x = jnp.arange(6.0, dtype=jnp.float32)
        (y,) = again(x, *args2[1:])
        np.testing.assert_allclose(np.asarray(y), np.cumsum(np.arange(6.0)) * 1.5)
    finally:
        jax.config.update("jax_compilation_cache_dir", old[0])
        jax.config.update("jax_persistent_cache_min_compile_time_secs", old[1])
        compilation_cache.reset_cache()


def test_reload_in_a_fresh_process_skips_scipy(tmp_path):
    """A reload deserialises the executable: no lowering, so no LAPACK set-up importing SciPy
    (≈ 0.2 s of the tracker's cached start, issue 13)."""
    code = (
        "import sys, jax, jax.numpy as jnp, numpy as np; "
        "sys.path.insert(0, 'tests/runtime'); from test_compiled import _cumsum_build; "
        "from cslx.runtime.compiled import cached_program; "
        f"call, args, _ = cached_program('c', _cumsum_build, directory={str(tmp_path)!r}); "
        "(y,) = call(jnp.arange(6.0, dtype=jnp.float32), *args[1:]); "
        "print(float(y[-1]), 'scipy' in sys.modules)"
    )
    root = pathlib.Path(__file__).resolve().parents[2]
    runs = [
        subprocess.run(
            [sys.executable, "-c", code], cwd=root, capture_output=True, text=True, check=True
        ).stdout.split()
        for _ in range(2)
    ]
    assert len(list((tmp_path / "cslx-export").iterdir())) == 1
    assert runs[0][0] == runs[1][0] == str(15.0 * 1.5)
    assert runs[1][1] == "False"  # the second process reloaded the file
