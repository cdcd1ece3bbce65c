"""Start-up without re-tracing: a jitted program exported once (`jax.export`) and reloaded.

JAX's persistent compilation cache (`cslx.environment.set_compile_cache`) spares a second
start-up XLA's compile, but not tracing the Python pipeline (equinox, optimistix, the
`lax` loops) and lowering it to StableHLO, which must happen before the cache can even be
looked up. `cached_program` keeps, in one file of the cache folder, the serialised
`jax.export.Exported` of a flat program (arrays in, a tuple of arrays out), its concrete
example arguments and a little JSON; a later start reads that file, lowers the small wrapper
that calls the program and finds the XLA executable in the persistent cache (issue 13,
start-up goal), without calling the code that builds the program. The tracker
(`cslx.runtime.tracker`) keeps its initial state and its summary's field names there, so a
cached start neither imports the pipeline (and MED, Steger, the weld features) nor runs
`init_state`. `compile_cached` is the same for a function of pytrees.

The file name is a hash of the caller's key (what the program closes over: settings, sensor
values, shapes), the source of the installed cslx package and the JAX version, so an edit
of the code or an upgrade never reloads a stale program. Without a cache folder it is plain
``jax.jit(fn).lower(*args).compile()``.

Where a cached start-up goes (the tracker, 640×480, `bench_speed`'s start-up probe with a
breakdown, fresh processes, CPU seconds on the 2-core machine at load 9–10, medians of 6):
importing JAX 0.41 s; importing the tracker and the sensor (equinox ≈ 0.2 s of it) 0.33 s
before, 0.24 s now (`cslx.runtime` and `cslx.segmentation` load their submodules on first
use; the pipeline only on a cache miss); building the default sensor 0.09 → 0.01 s (NumPy and
`jax.device_put` instead of 7 small eager XLA programs); loading the cached program ≈ 0.75 s,
most of it XLA's deserialisation of the executable (its size: ≈ 17 000 optimised HLO
instructions, a quarter of them the weld features); the first frame 0.03 s. Loading a
serialised executable directly (`jax.experimental.serialize_executable`) instead of the
exported program saved ≈ 0.1 s CPU of the ≈ 0.7 s, within the scatter at that load, and an
executable read back from the persistent cache and serialised again failed to run ("Function
… not found"): not adopted. Tried and not adopted earlier:
``--xla_cpu_parallel_codegen_split_count=1`` (executable load 1.04–1.40 s against
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
            source of cslx, the JAX version and the platform are added here).
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
    import numpy as np

    directory = directory or jax.config.jax_compilation_cache_dir
    try:
        import flatbuffers  # noqa: F401  (jax.export's serialisation needs it)
    except ImportError:
        directory = None
    if not directory:
        fn, args, meta = build()
        return jax.jit(fn).lower(*args).compile(), tuple(args), meta
    import jaxlib

    platform = jax.default_backend()
    ident = "|".join(
        [key, source_digest(), jax.__version__, jaxlib.__version__, platform]
    )  # fmt: skip
    name = hashlib.sha256(ident.encode()).hexdigest()[:32]
    path = pathlib.Path(directory) / "cslx-export" / f"{name}.npz"
    loaded = _load(path) if path.is_file() else None
    if loaded is None:
        fn, args, meta = build()
        exported = jax.export.export(jax.jit(fn))(*args)
        concrete = {
            f"arg{i}": np.asarray(a)
            for i, a in enumerate(args)
            if not isinstance(a, jax.ShapeDtypeStruct)
        }
        blob = np.frombuffer(bytes(exported.serialize()), np.uint8)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}.npz")
        np.savez(tmp, exported=blob, meta=np.asarray(json.dumps(meta)), **concrete)
        os.replace(tmp, path)
        args = tuple(args)
    else:
        exported, args, meta = loaded
    specs = [jax.ShapeDtypeStruct(a.shape, a.dtype) for a in exported.in_avals]
    return jax.jit(exported.call).lower(*specs).compile(), args, meta


def _load(path: pathlib.Path):
    """(exported, args, meta) from a `cached_program` file; None if it cannot be read."""
    import jax
    import numpy as np

    try:
        with np.load(path) as z:
            exported = jax.export.deserialize(bytearray(z["exported"].tobytes()))
            meta = json.loads(str(z["meta"]))
            args = tuple(
                jax.device_put(z[f"arg{i}"])
                if f"arg{i}" in z.files
                else jax.ShapeDtypeStruct(a.shape, a.dtype)
                for i, a in enumerate(exported.in_avals)
            )
    except Exception:  # a truncated or foreign file: export again
        return None
    return exported, args, meta
