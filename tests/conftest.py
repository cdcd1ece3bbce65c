"""Test configuration: numerics run in float64 (docs/architecture.md); the library never flips it.

Like every entry point, the tests set the process-wide settings explicitly
(`cslx.environment.configure`: single-threaded BLAS, a quiet CPU start) before JAX loads,
and share one persistent compile cache across the xdist workers.

The test run is mostly compile time (a whole-pipeline program takes 15–45 CPU seconds to
compile), so the tests — and the commands they start, which inherit the variable — compile
at XLA's backend optimisation level 0 (`TEST_XLA_FLAGS`): the same HLO passes and the same
floating-point semantics, LLVM's machine-code optimisations skipped. The full-frame program
compiled in 13–15 instead of 29–35 CPU seconds, the tracking-band program in 18–21 instead of
38–47 (two of each, alternating, on the loaded development machine). Speed is measured by
`experiments/`, which compile at the default level; ``CSLX_TEST_XLA_OPT=default`` runs the
tests at the default level too.
"""

import os
import pathlib

#: XLA flags the test session adds (module docstring); CSLX_TEST_XLA_OPT=default drops them.
TEST_XLA_FLAGS = "--xla_backend_optimization_level=0"
if os.environ.get("CSLX_TEST_XLA_OPT", "").strip().lower() != "default":
    if "xla_backend_optimization_level" not in os.environ.get("XLA_FLAGS", ""):
        os.environ["XLA_FLAGS"] = f"{os.environ.get('XLA_FLAGS', '')} {TEST_XLA_FLAGS}".strip()

from cslx.environment import configure  # noqa: E402

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
