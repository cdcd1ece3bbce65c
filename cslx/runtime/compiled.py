"""Start-up without re-tracing or lowering: a compiled program serialised once and reloaded.

JAX's persistent compilation cache (`cslx.environment.set_compile_cache`) spares a second
start-up XLA's compile, but not tracing the Python pipeline (equinox, optimistix, the
`lax` loops) and lowering it to StableHLO, which must happen before the cache can even be
looked up. `cached_program` keeps, in one file of the cache folder, the serialised XLA
executable of a flat program (arrays in, a tuple of arrays out;
`jax.experimental.serialize_executable`), its concrete example arguments and a little JSON;
a later start reads that file and deserialises the executable (issue 13, start-up goal),
without calling the code that builds the program and without lowering anything. The tracker
(`cslx.runtime.tracker`) keeps its initial state and its summary's field names there, so a
cached start neither imports the pipeline (and MED, Steger, the weld features) nor runs
`init_state`. `compile_cached` is the same for a function of pytrees.

The file name is a hash of the caller's key (what the program closes over: settings, sensor
values, shapes), the source of the installed cslx package, the JAX version, the platform
and the host CPU (the executable is machine code for it), so an edit of the code, an
upgrade or another machine sharing the folder never reloads a stale program. The file is
written from a fresh compile with JAX's persistent cache switched off: an executable that
XLA read back from that cache serialises without its machine code and fails when run
("Function … not found"). A file that cannot be read is compiled again. Without a cache
folder it is plain ``jax.jit(fn).lower(*args).compile()``. Like JAX's own cache, the file
is trusted: deserialising it loads machine code (keep the folder private).

Where a cached start-up goes (the tracker, 640×480, `bench_speed`'s start-up probe with a
breakdown, fresh processes on the 2-core machine, medians of interleaved runs). At load 3–4
(6 pairs, wall s): importing JAX 0.40–0.46 s; importing the tracker and the sensor 0.18–0.20
s (equinox ≈ 0.14 s CPU of it); building the default sensor 0.06 s; loading the program 0.84
s with the exported program → 0.52 s with the serialised executable; the first frame 0.05 s;
process start → first frame 1.60 → 1.42 s. Then equinox left the path (`cslx.pytree`: the
sensor, its camera and the weld detector's settings are frozen dataclasses registered as
pytrees): importing the tracker and the sensor 0.46 → 0.13 s wall at load 7–8 (6 pairs). All
three in one run at load 8–9 (5 rounds; wall is ≈ 2.5× CPU at that load, so CPU s is the
figure to compare): process CPU 1.95 s (exported program) → 1.79 s (serialised executable) →
1.46 s (and no equinox), wall 4.6 → 4.3 → 3.7 s. Then jaxtyping (annotations only, now
imported for type checkers alone): importing the tracker and the sensor 0.09 → 0.05 s wall,
process CPU 1.22 → 1.14 s (load 8, 6 pairs). `bench_speed`'s own start-up worker, before
(exported program, equinox) against after (serialised executable, no equinox), 6 interleaved
pairs at load 7 (the first after-run compiled: 5 counted): process start → first frame 2.09
→ 1.65 s (CPU 1.99 → 1.63 s); the garbage collector off during start-up (as ``cslx track``
has it) saves ≈ 0.05 s CPU more. What is left (CPU, quiet machine): importing NumPy and JAX
≈ 0.45 s, cslx's modules ≈ 0.05 s, XLA's deserialisation of the executable ≈ 0.45–0.5 s, the
first frame (the σ / colour check and the program) ≈ 0.05 s.

Later, with ml_dtypes 0.7.0 installed (JAX imports it), the start-up went back up: its
import takes 0.55 s CPU (0.6.0: 0.01 s; most of it in NumPy's ``PyUFunc_AddLoop`` comparing
the signatures of the ufunc loops it registers), so pyproject.toml asks for
``ml_dtypes<0.7``. `cslx track --dry-run --max-frames 1` on a PNG folder, process start →
first frame, 5 interleaved pairs at load 8.3–8.6 (fresh processes, wall s / CPU s, medians):
3.39 / 1.66 (0.7.0) → 2.21 / 1.10 (0.6.0). Where the 1.10 s CPU goes: interpreter and
`cslx.cli` 0.04, `configure`, logging and the runtime's light modules 0.05, NumPy 0.06, JAX
0.32, the tracker's modules, cv2 and the calibration file 0.03, XLA's deserialisation of the
executable 0.54 (on one XLA thread, the caller waiting with the GIL released), the first
frame 0.06 (PNG decode, the σ / colour check 0.03, the program's first run; the second frame
0.025). Tried and not adopted: loading the executable in a background thread while the first
frame is decoded and checked (the work it could overlap is ≈ 0.04 s CPU, below the scatter
here); locations capped (``jax_traceback_in_locations_limit`` 0: 3.6 → 3.1 MB,
deserialisation 0.49 → 0.46 s CPU, 5 pairs); glibc's fast bins off (``mallopt(M_MXFAST,
0)``: 0.50 → 0.46 s CPU, 4 pairs); the garbage collector off during start-up saves 0.05 s
CPU (as before). What remains is JAX's import and XLA's rebuilding of the program's ≈ 17 000
HLO instructions: a smaller first-frame program (one Steger copy instead of one per
`lax.cond` branch) is the next lever.

Before, a cached start deserialised a `jax.export.Exported` (the StableHLO), lowered the
wrapper calling it (0.34 s, 0.21 s of it importing SciPy: the lowering of an exported call
sets up JAX's LAPACK kernels, which load SciPy, although this program calls no LAPACK) and
then read the executable from JAX's persistent cache; now the whole load is XLA's
deserialisation of the executable (a 3.7 MB file), which scales with the program's
≈ 17 000 optimised HLO instructions in 1 300 computations (of those with a source
location, the weld features 37 %, three Steger copies, one per `lax.cond` branch of the
pipeline, 31 %): rebuilding the HLO module from its proto is ≈ 45 % of it, buffer
assignment, alias analysis, the thunks and linking the machine code most of the rest. Tried
and not adopted: stripping the locations (HLO metadata, 3.7 → 2.9 MB) loaded ≈ 10 %
faster in 4 pairs at load 10, within the scatter, and needs JAX internals; fewer traceback
frames in the locations (``jax_include_full_tracebacks_in_locations``: 3.7 → 3.2 MB) no
change; ``--xla_cpu_parallel_codegen_split_count=1`` (executable load 1.04–1.40 s against
1.30–1.54 s, three interleaved pairs at load 6–9: not decisive for a process-wide flag).
"""

from __future__ import annotations

import functools
import hashlib
import json
import os
import pathlib

__all__ = ["cached_program", "compile_cached", "source_digest", "tree_digest"]


@functools.lru_cache(maxsize=1)
def source_digest() -> str:
    """SHA-256 over the source files of the cslx package (names and contents)."""
    root = pathlib.Path(__file__).resolve().parents[1]
    h = hashlib.sha256()
    for path in sorted(root.rglob("*.py")):
        h.update(str(path.relative_to(root)).encode())
        h.update(path.read_bytes())
    return h.hexdigest()


def tree_digest(tree) -> str:
    """SHA-256 of a pytree's structure, array dtypes, shapes and values, and other leaves."""
    import jax
    import numpy as np

    leaves, treedef = jax.tree_util.tree_flatten(tree)
    h = hashlib.sha256(str(treedef).encode())
    for x in leaves:
        if isinstance(x, jax.ShapeDtypeStruct):
            h.update(f"spec{x.dtype}{x.shape}".encode())
        elif hasattr(x, "dtype") and hasattr(x, "shape"):
            a = np.asarray(x)
            h.update(f"{a.dtype}{a.shape}".encode())
            h.update(a.tobytes())
        else:
            h.update(repr(x).encode())
    return h.hexdigest()


def compile_cached(fn, args: tuple, out_like, key: str, directory: str | os.PathLike | None = None):
    """``jax.jit(fn).lower(*args).compile()``, with the traced program kept on disk.

    Args:
        fn: the function to compile (its closure is part of the program: put what it
            closes over into ``key``).
        args: example arguments or `jax.ShapeDtypeStruct`s (pytrees allowed).
        out_like: any pytree with the structure of ``fn``'s result (leaves ignored): the
            exported program works on flat lists of arrays, so custom pytree types (the
            pipeline's state) need no serialisation, and a reload knows the result's
            structure without tracing ``fn``.
        key: text naming what ``fn`` closes over (see `tree_digest`).
        directory: folder of the exported programs; default the persistent compilation
            cache's (``jax_compilation_cache_dir``), else no export.

    Returns:
        A callable with ``fn``'s signature running the compiled program.
    """
    import jax

    in_leaves, in_tree = jax.tree_util.tree_flatten(args)
    out_tree = jax.tree_util.tree_structure(out_like)

    def build():
        def flat(*leaves):
            out = fn(*jax.tree_util.tree_unflatten(in_tree, leaves))
            out_leaves, tree = jax.tree_util.tree_flatten(out)
            if tree != out_tree:
                raise ValueError(f"compile_cached: result structure {tree} is not {out_tree}")
            return tuple(out_leaves)

        return flat, in_leaves, {}

    ident = f"{key}|{tree_digest(args)}|{out_tree}"
    compiled, _, _ = cached_program(ident, build, directory)

    def call(*a):
        out = compiled(*jax.tree_util.tree_leaves(a))
        return jax.tree_util.tree_unflatten(out_tree, out)

    return call


def cached_program(key: str, build, directory: str | os.PathLike | None = None):
    """A compiled flat program with its example arguments, reloaded without calling ``build``.

    Args:
        key: text naming everything the program and its example arguments depend on (the
            source of cslx, the JAX version, the platform and the host CPU are added here).
        build: ``build() -> (fn, args, meta)``: ``fn`` takes the flat ``args`` (arrays, or
            `jax.ShapeDtypeStruct`s for inputs given only by shape) and returns a tuple of
            arrays; ``meta`` is a JSON-able dict. Called only when the program is not on disk
            (or without a cache folder), so its imports and tracing cost nothing at a cached
            start.
        directory: as in `compile_cached`.

    Returns:
        ``(call, args, meta)``: the compiled program (``call(*args) -> tuple``), the example
        arguments (concrete ones as device arrays, the others as `jax.ShapeDtypeStruct`s) and
        ``meta``; all three kept in one file, so a reload needs neither ``build`` nor the
        modules it imports.
    """
    import jax

    directory = directory or jax.config.jax_compilation_cache_dir
    if not directory:
        fn, args, meta = build()
        return jax.jit(fn).lower(*args).compile(), tuple(args), meta
    path = pathlib.Path(directory) / "cslx-export" / f"{_file_name(key)}.npz"
    loaded = _load(path) if path.is_file() else None
    if loaded is not None:
        return loaded
    fn, args, meta = build()
    args = tuple(args)
    compiled = _fresh_compile(fn, args)
    _save(path, compiled, args, meta)
    return compiled, args, meta


def _file_name(key: str) -> str:
    """The cache file's name: a hash of the key, cslx's source, JAX, the platform, the CPU."""
    import jax
    import jaxlib

    ident = "|".join(
        [key, source_digest(), jax.__version__, jaxlib.__version__, jax.default_backend(),
         _host_cpu()]
    )  # fmt: skip
    return hashlib.sha256(ident.encode()).hexdigest()[:32]


def _host_cpu() -> str:
    """The host CPU's model and instruction-set flags (a serialised CPU executable is machine
    code for them, so a cache folder shared with another machine must not hand it over)."""
    import platform

    found = {}
    try:
        with open("/proc/cpuinfo") as f:
            for line in f:
                name, _, value = line.partition(":")
                name = name.strip()
                if name in ("model name", "flags") and name not in found:
                    found[name] = value.strip()
                if len(found) == 2:
                    break
    except OSError:
        pass
    return f"{platform.machine()}|{found.get('model name', '')}|{found.get('flags', '')}"


def _fresh_compile(fn, args):
    """``jax.jit(fn).lower(*args).compile()`` with JAX's persistent cache switched off.

    An executable that XLA read back from that cache serialises without its machine code (it
    then fails with "Function … not found" when run), so the one written here is always
    compiled anew. The cache is switched on again afterwards as it was.
    """
    import jax
    from jax.experimental.compilation_cache import compilation_cache

    enabled = jax.config.jax_enable_compilation_cache
    compilation_cache.reset_cache()
    jax.config.update("jax_enable_compilation_cache", False)
    try:
        return jax.jit(fn).lower(*args).compile()
    finally:
        jax.config.update("jax_enable_compilation_cache", enabled)
        compilation_cache.reset_cache()


def _save(path: pathlib.Path, compiled, args: tuple, meta: dict) -> None:
    """Write the serialised executable, the concrete example arguments and the meta data."""
    import jax
    import numpy as np
    from jax.experimental import serialize_executable

    blob, _, _ = serialize_executable.serialize(compiled)
    concrete = {
        f"arg{i}": np.asarray(a)
        for i, a in enumerate(args)
        if not isinstance(a, jax.ShapeDtypeStruct)
    }
    specs = [[list(a.shape), np.dtype(a.dtype).str] for a in args]
    n_out = len(jax.tree_util.tree_leaves(compiled.out_info))
    info = dict(meta=meta, specs=specs, n_out=n_out)
    path.parent.mkdir(parents=True, exist_ok=True)
    tmp = path.with_suffix(f".tmp{os.getpid()}.npz")
    np.savez(
        tmp, executable=np.frombuffer(blob, np.uint8), info=np.asarray(json.dumps(info)), **concrete
    )
    os.replace(tmp, path)


def _load(path: pathlib.Path):
    """(compiled, args, meta) from a `cached_program` file; None if it cannot be read."""
    import jax
    import numpy as np
    from jax.experimental import serialize_executable

    try:
        with np.load(path) as z:
            info = json.loads(str(z["info"]))
            specs = [jax.ShapeDtypeStruct(tuple(s), np.dtype(d)) for s, d in info["specs"]]
            in_tree = jax.tree_util.tree_structure(((0,) * len(specs), {}))
            out_tree = jax.tree_util.tree_structure((0,) * info["n_out"])
            compiled = serialize_executable.deserialize_and_load(
                z["executable"].tobytes(), in_tree, out_tree
            )
            args = tuple(
                jax.device_put(z[f"arg{i}"]) if f"arg{i}" in z.files else spec
                for i, spec in enumerate(specs)
            )
    except Exception:  # a truncated, foreign or outdated file: compile again
        return None
    return compiled, args, info["meta"]
