"""Test configuration: the numerics tests run in float64 (STYLE.md); the library never flips it."""

import os
import pathlib

os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")  # see cslx.cli: threaded Cholesky stalls

import jax  # noqa: E402

jax.config.update("jax_enable_x64", True)
# One compile cache for all xdist workers: repeated jit compiles across tests are the slow part.
jax.config.update(
    "jax_compilation_cache_dir", os.path.join(os.path.dirname(__file__), "..", ".jax_cache")
)
jax.config.update("jax_persistent_cache_min_compile_time_secs", 1.0)

SHARED = pathlib.Path(__file__).resolve().parents[1].parent / "shared"
