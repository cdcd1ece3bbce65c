"""Keep OpenBLAS single-threaded.

JAX's CPU linear algebra (the Cholesky solve of MED's Toeplitz system) calls LAPACK through
SciPy's OpenBLAS. On a loaded 2-core machine OpenBLAS's threaded Cholesky of a 240–320 sized
matrix was 100–1000× slower than single-threaded (one MED iteration took 175–760 ms instead
of 0.5 ms), and XLA already runs its own threads. Setting OPENBLAS_NUM_THREADS works only
before NumPy loads, so cslx also limits the BLAS thread pools at import with threadpoolctl.
Set the environment variable CSLX_BLAS_THREADS (an integer, or "off" to leave BLAS alone)
to change it.
"""

from __future__ import annotations

import os

_limiter = None


def limit_blas_threads() -> None:
    """Limit every loaded BLAS library to CSLX_BLAS_THREADS threads (default 1)."""
    global _limiter
    setting = os.environ.get("CSLX_BLAS_THREADS", "1").strip().lower()
    if setting in ("off", "none", ""):
        return
    os.environ.setdefault("OPENBLAS_NUM_THREADS", setting)
    try:
        import scipy.linalg  # noqa: F401  (load SciPy's OpenBLAS so that it is limited too)
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    _limiter = threadpool_limits(limits=int(setting), user_api="blas")
