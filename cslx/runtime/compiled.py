"""Start-up without re-tracing: a jitted program exported once (`jax.export`) and reloaded.

JAX's persistent compilation cache (`cslx.environment.set_compile_cache`) spares a second
start-up XLA's compile, but not tracing the Python pipeline (equinox, optimistix, the
`lax` loops) and lowering it to StableHLO, which must happen before the cache can even be
looked up. `compile_cached` keeps the serialised `jax.export.Exported` of the program in the
cache folder; a later start deserialises it (no tracing), lowers the small wrapper that
calls it and finds the XLA executable in the persistent cache (issue 13, start-up goal).

The file name is a hash of the caller's key (what the program closes over: settings, sensor
values, shapes), the source of the installed cslx package and the JAX version, so an edit
of the code or an upgrade never reloads a stale program. Without a cache folder it is plain
``jax.jit(fn).lower(*args).compile()``.
"""

from __future__ import annotations

import functools
import hashlib
import os
import pathlib

__all__ = ["compile_cached", "source_digest", "tree_digest"]


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

    directory = directory or jax.config.jax_compilation_cache_dir
    try:
        import flatbuffers  # noqa: F401  (jax.export's serialisation needs it)
    except ImportError:
        directory = None
    if not directory:
        return jax.jit(fn).lower(*args).compile()
    import jaxlib

    in_leaves, in_tree = jax.tree_util.tree_flatten(args)
    out_tree = jax.tree_util.tree_structure(out_like)

    def flat(*leaves):
        out = fn(*jax.tree_util.tree_unflatten(in_tree, leaves))
        out_leaves, tree = jax.tree_util.tree_flatten(out)
        if tree != out_tree:
            raise ValueError(f"compile_cached: result structure {tree} is not {out_tree}")
        return tuple(out_leaves)

    platform = jax.default_backend()
    ident = "|".join(
        [key, tree_digest(args), str(out_tree), source_digest(), jax.__version__,
         jaxlib.__version__, platform]
    )  # fmt: skip
    name = hashlib.sha256(ident.encode()).hexdigest()[:32]
    path = pathlib.Path(directory) / "cslx-export" / f"{name}.jaxexport"
    exported = None
    if path.is_file():
        try:
            exported = jax.export.deserialize(bytearray(path.read_bytes()))
        except Exception:  # a truncated or foreign file: export again
            exported = None
    if exported is None:
        exported = jax.export.export(jax.jit(flat))(*in_leaves)
        path.parent.mkdir(parents=True, exist_ok=True)
        tmp = path.with_suffix(f".tmp{os.getpid()}")
        tmp.write_bytes(exported.serialize())
        os.replace(tmp, path)
    compiled = jax.jit(exported.call).lower(*in_leaves).compile()

    def call(*a):
        out = compiled(*jax.tree_util.tree_leaves(a))
        return jax.tree_util.tree_unflatten(out_tree, out)

    return call
