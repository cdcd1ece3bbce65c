"""Test configuration: numerics run in float64 (docs/architecture.md); the library never flips it.

Like every entry point, the tests set the process-wide settings explicitly
(`cslx.environment.configure`: single-threaded BLAS, a quiet CPU start) before JAX loads,
and share one persistent compile cache across the xdist workers.
"""

import os
import pathlib

from cslx.environment import configure

#: The compile cache of the test session; subprocesses under test use it too (tests/cli).
JAX_CACHE = os.path.abspath(os.path.join(os.path.dirname(__file__), "..", ".jax_cache"))
configure(compile_cache=JAX_CACHE)

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

import pytest  # noqa: E402

SHARED = pathlib.Path(__file__).resolve().parents[1].parent / "shared"


@pytest.fixture(scope="session")
def jax_cache():
    """The session's persistent compile cache (`JAX_CACHE`), for commands run under test:
    every xdist worker and subprocess then compiles a program once for the whole run."""
    return JAX_CACHE
