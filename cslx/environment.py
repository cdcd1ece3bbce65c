"""Process-wide settings that entry points set explicitly; importing cslx sets none of them.

- **BLAS threads.** JAX's CPU linear algebra (the Cholesky solve of MED's Toeplitz system)
  calls LAPACK through SciPy's OpenBLAS. On a loaded 2-core machine OpenBLAS's threaded
  Cholesky of a 240–320 sized matrix was 100–1000× slower than single-threaded (one MED
  iteration took 175–760 ms instead of 0.5 ms), and XLA already runs its own threads.
  `OPENBLAS_NUM_THREADS` works only before NumPy loads, so `configure` sets it and, when
  NumPy or SciPy is already loaded (or the variable was set to another value), also limits
  the BLAS pools with threadpoolctl.
- **Compile cache.** A persistent XLA compilation cache makes the second start of a
  command (the tracker's 12–20 s compile) take a fraction of a second.
- **Small loops in one kernel.** XLA's CPU backend runs a while loop as one kernel call
  per operation of its body per trip (the tracking frame: ≈ 8 500 kernel calls, most of them
  in the weld features' median bisections and IRLS loops and the clipped-core fill's scans);
  a loop whose body touches fewer than ``xla_cpu_small_while_loop_byte_threshold`` bytes
  is compiled into a single function instead. `configure` raises that threshold to
  `SMALL_LOOP_BYTES` (``CSLX_XLA_SMALL_LOOPS``: another byte count, or "off") in
  ``XLA_FLAGS`` (read once, when JAX starts its CPU backend) unless the caller set
  ``xla_backend_extra_options`` there. The default lets every loop without a library call
  (LAPACK, a custom call) go: the tracking frame's executed kernels ≈ 17 100 → 4 500 trace
  events (`jax.profiler`), outputs identical, and in two processes run in lockstep, frame
  for frame alternately (issue 13, load 6–7, sunny video seed 0): tracking mode with MED
  5.17 → 4.98 and 4.69 → 4.62 ms median (p10 4.04 → 3.87, 3.80 → 3.68; 600 and 800
  frames), the tracker's tracking mode 3.78 → 3.67 ms, a cold frame 10.02 → 9.76 ms; a
  20 kB threshold 5.07 → 5.16 ms (no gain).
- **One-thread backend (opt-in).** `one_thread_backend`: XLA's and YNNPACK's CPU thread
  pools sized for one core; on the loaded 2-core machine a split kernel waits for its
  slowest part (numbers there).
- **Quiet CPU start.** On a machine without accelerators JAX probes for a TPU backend and
  logs a warning; `configure` pins the platform to the CPU when nothing else is asked for.

The `cslx` command line, the experiments, the notebooks and the tests call `configure()`
first; a robot runtime that imports cslx decides for itself.
"""

from __future__ import annotations

import os
import sys

__all__ = ["configure", "limit_blas_threads", "set_compile_cache", "small_loops"]
__all__ += ["SMALL_LOOP_BYTES", "one_thread_backend"]

#: XLA CPU: while loops touching fewer bytes a trip run as one function each (`small_loops`).
SMALL_LOOP_BYTES = 1_000_000_000

_limiter = None


def limit_blas_threads(threads: int | str | None = None) -> None:
    """Limit every BLAS library of this process to `threads` (default CSLX_BLAS_THREADS or 1).

    "off" leaves BLAS alone.
    """
    global _limiter
    setting = str(threads if threads is not None else os.environ.get("CSLX_BLAS_THREADS", "1"))
    setting = setting.strip().lower()
    if setting in ("off", "none", ""):
        return
    os.environ.setdefault("OPENBLAS_NUM_THREADS", setting)
    if os.environ["OPENBLAS_NUM_THREADS"] == setting and not {"numpy", "scipy"} & set(sys.modules):
        # No BLAS loaded yet: NumPy's and SciPy's OpenBLAS read the variable when they load.
        # Importing SciPy here to limit it at once cost ≈ 0.2 s of every start-up (issue 13).
        return
    try:
        import scipy.linalg  # noqa: F401  (load SciPy's OpenBLAS so that it is limited too)
        from threadpoolctl import threadpool_limits
    except ImportError:
        return
    _limiter = threadpool_limits(limits=int(setting), user_api="blas")


def small_loops(threshold: int | str | None = None) -> None:
    """Let XLA's CPU backend compile while loops of fewer than ``threshold`` bytes per trip
    (default CSLX_XLA_SMALL_LOOPS, else `SMALL_LOOP_BYTES`; "off" leaves XLA's default) as
    one function each, through ``XLA_FLAGS`` (module docstring). Effective only before JAX
    starts its CPU backend; a caller's own ``xla_backend_extra_options`` is left alone."""
    default = os.environ.get("CSLX_XLA_SMALL_LOOPS", SMALL_LOOP_BYTES)
    setting = str(threshold if threshold is not None else default).strip().lower()
    flags = os.environ.get("XLA_FLAGS", "")
    if setting in ("off", "none", "") or "xla_backend_extra_options" in flags:
        return
    option = f"--xla_backend_extra_options=xla_cpu_small_while_loop_byte_threshold={int(setting)}"
    os.environ["XLA_FLAGS"] = f"{flags} {option}".strip()


def one_thread_backend() -> bool:
    """Start JAX's CPU backend sized for one core, then give the process all its cores back.

    XLA's CPU runtime splits large loops across a thread pool and YNNPACK runs reductions
    on its own pool, both sized by the cores the process may run on when the backend
    starts; each such kernel then waits for its slowest part. The process is restricted to
    one core while the backend starts (its pools are built for one thread) and released
    to all of its cores after (every thread of the process). Linux only; returns whether
    it applied. Outputs are unchanged (the same kernels, not split).

    Opt-in (`configure`'s ``one_thread``, ``CSLX_ONE_THREAD=1``): the tracking loop gains on
    a loaded machine, the cold full frame loses. Issue 13, two processes in lockstep, frame
    for frame alternately (`experiments.ab_flags --one-thread b`, the same XLA flags; sunny
    video seed 0; identical outputs), median ms:

    - tracking mode with MED in the bands: 4.82 → 3.74 (300 frames, load 5–6), 5.26 → 4.99
      (300, load 6–7), but 4.40 → 4.55 (400, load 2.6): it pays when the other core is busy;
    - the tracker's `tracking_config`: 3.97 → 3.76 (200, load 7);
    - a cold frame with first-pass bands: 10.36 → 7.89 (200, load 6.5);
    - the cold full frame (``roi=False``, large FFTs): 17.68 → 19.20 (80, load 5–6): slower.

    The process pinned to one core instead: tracking with MED 7.56 → 5.53 ms (load 11),
    and 4.83 against this one's 4.86 ms (load 5–7): the pools' size is what pays.
    """
    if not hasattr(os, "sched_setaffinity"):
        return False
    cpus = os.sched_getaffinity(0)
    if len(cpus) < 2:
        return False
    os.sched_setaffinity(0, {min(cpus)})
    try:
        import jax

        jax.devices()  # the backend and its thread pools start now
    finally:
        for tid in os.listdir("/proc/self/task"):
            try:
                os.sched_setaffinity(int(tid), cpus)
            except OSError:
                pass
    return True


def set_compile_cache(directory: str | os.PathLike, min_compile_s: float = 0.0) -> None:
    """Use a persistent XLA compilation cache in `directory` (created if missing)."""
    import jax

    os.makedirs(directory, exist_ok=True)
    jax.config.update("jax_compilation_cache_dir", os.fspath(directory))
    jax.config.update("jax_persistent_cache_min_compile_time_secs", float(min_compile_s))


def configure(
    *,
    blas_threads: int | str | None = None,
    compile_cache: str | os.PathLike | None = None,
    quiet_cpu: bool = True,
    small_loop_bytes: int | str | None = None,
    one_thread: bool | None = None,
) -> None:
    """Set the process-wide settings an entry point wants (see the module docstring).

    Args:
        blas_threads: BLAS threads (default: CSLX_BLAS_THREADS, else 1; "off" to leave alone).
        compile_cache: a persistent compilation cache folder (default: CSLX_JAX_CACHE, if set).
        quiet_cpu: when JAX_PLATFORMS is unset and no accelerator plugin is installed, pin
            JAX to the CPU so that it does not probe (and warn about) a TPU backend.
        small_loop_bytes: `small_loops`'s threshold (default: CSLX_XLA_SMALL_LOOPS, else
            `SMALL_LOOP_BYTES`; "off" for XLA's default).
        one_thread: start JAX's CPU backend with one-thread pools (`one_thread_backend`;
            default: CSLX_ONE_THREAD is 1 / true / on). Starts JAX.
    """
    if quiet_cpu and "JAX_PLATFORMS" not in os.environ and not _accelerator_installed():
        os.environ["JAX_PLATFORMS"] = "cpu"
    limit_blas_threads(blas_threads)
    small_loops(small_loop_bytes)
    cache = compile_cache or os.environ.get("CSLX_JAX_CACHE")
    if cache:
        set_compile_cache(cache)
    if one_thread is None:
        one_thread = os.environ.get("CSLX_ONE_THREAD", "").strip().lower() in ("1", "true", "on")
    if one_thread:
        one_thread_backend()


def _accelerator_installed() -> bool:
    import importlib.util

    return any(
        importlib.util.find_spec(name) is not None
        for name in ("jax_cuda12_plugin", "jax_cuda13_plugin", "jax_rocm60_plugin", "libtpu")
    )
