"""Test configuration: numerics run in float64 (docs/architecture.md); the library never flips it.

Like every entry point, the tests set the process-wide settings explicitly
(`cslx.environment.configure`: single-threaded BLAS, a quiet CPU start) before JAX loads,
and share one persistent compile cache across the xdist workers.
"""

import os
import pathlib

from cslx.environment import configure

configure(compile_cache=os.path.join(os.path.dirname(__file__), "..", ".jax_cache"))

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

SHARED = pathlib.Path(__file__).resolve().parents[1].parent / "shared"
