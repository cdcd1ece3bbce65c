"""`cslx.environment.configure`: single-threaded BLAS without loading SciPy at start-up."""

import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]


def test_blas_limited_without_importing_scipy():
    """Before NumPy loads, the variable alone limits every OpenBLAS that loads later; SciPy
    (≈ 0.2 s) is not imported by `configure` (issue 13, start-up)."""
    code = (
        "import sys; from cslx.environment import configure; configure(); "
        "print('scipy' in sys.modules, 'numpy' in sys.modules); "
        "import numpy, scipy.linalg; from threadpoolctl import threadpool_info; "
        "print(sorted({i['num_threads'] for i in threadpool_info() if i['user_api'] == 'blas'}))"
    )
    env = {k: v for k, v in os.environ.items() if k != "OPENBLAS_NUM_THREADS"}
    env.pop("CSLX_BLAS_THREADS", None)
    out = subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    ).stdout.splitlines()
    assert out == ["False False", "[1]"]


def _xla_flags(env_extra: dict) -> str:
    code = (
        "import os; from cslx.environment import configure; configure(); "
        "print(os.environ.get('XLA_FLAGS', ''))"
    )
    env = {k: v for k, v in os.environ.items() if k not in ("XLA_FLAGS", "CSLX_XLA_SMALL_LOOPS")}
    env.update(env_extra)
    return subprocess.run(
        [sys.executable, "-c", code], cwd=ROOT, env=env, capture_output=True, text=True, check=True
    ).stdout.strip()


def test_small_loops_flag():
    """`configure` lets XLA's CPU backend compile small while loops as one function (the
    threshold in XLA_FLAGS), keeps the caller's flags, and leaves a caller's own backend
    options (or "off") alone."""
    from cslx.environment import SMALL_LOOP_BYTES

    option = "--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold="
    assert _xla_flags({}) == f"{option}{SMALL_LOOP_BYTES}"
    assert _xla_flags({"CSLX_XLA_SMALL_LOOPS": "5000"}) == f"{option}5000"
    assert _xla_flags({"XLA_FLAGS": "--xla_cpu_enable_fast_min_max=true"}) == (
        f"--xla_cpu_enable_fast_min_max=true {option}{SMALL_LOOP_BYTES}"
    )
    own = "--xla_backend_extra_options=other=1"
    assert _xla_flags({"XLA_FLAGS": own}) == own
    assert _xla_flags({"CSLX_XLA_SMALL_LOOPS": "off"}) == ""


def test_one_thread_backend_gives_the_cores_back():
    """`one_thread_backend` (issue 13) restricts the process to one core only while JAX's
    backend starts: afterwards every thread may run on all the cores it had before."""
    import pytest

    from cslx.environment import one_thread_backend

    if not hasattr(os, "sched_getaffinity"):
        pytest.skip("no CPU affinity on this platform")
    before = os.sched_getaffinity(0)
    applied = one_thread_backend()
    assert applied == (len(before) > 1)
    for tid in os.listdir("/proc/self/task"):
        assert os.sched_getaffinity(int(tid)) == before


def test_test_session_compiles_at_level_0_and_passes_it_on():
    """tests/conftest.py: the session compiles at XLA's backend optimisation level 0
    (`TEST_XLA_FLAGS`, unless CSLX_TEST_XLA_OPT=default) and a command it starts inherits
    the flag beside the library's own (`configure`'s small-loop option)."""
    from tests.conftest import TEST_XLA_FLAGS

    wanted = os.environ.get("CSLX_TEST_XLA_OPT", "").strip().lower() != "default"
    assert (TEST_XLA_FLAGS in os.environ.get("XLA_FLAGS", "").split()) == wanted
    code = (
        "from cslx.environment import configure; configure(); "
        "import os; print(os.environ['XLA_FLAGS'])"
    )
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, check=True)
    flags = out.stdout.split()
    assert (TEST_XLA_FLAGS in flags) == wanted
    assert any(f.startswith("--xla_backend_extra_options=") for f in flags)
