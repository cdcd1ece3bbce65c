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
