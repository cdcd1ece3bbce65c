"""Immutable pytrees without equinox: frozen dataclasses registered with JAX (issue 13).

Importing equinox costs ≈ 0.14 s of CPU, a tenth of the tracker's cached start-up
(`cslx.runtime.compiled`), so the classes that start-up needs (the sensor and its camera,
the bead detector's settings) are made with `pytree_dataclass` instead of `equinox.Module`:
the same immutable dataclass and the same pytree (each field a child, in field order),
except that a field made with `static` is static, part of the tree's structure, as
``eqx.field(static=True)``.
"""

from __future__ import annotations

import dataclasses

import jax

__all__ = ["pytree_dataclass", "static"]


def pytree_dataclass(cls=None, *, eq: bool = True):
    """``@dataclasses.dataclass(frozen=True, eq=eq)`` registered as a JAX pytree.

    ``eq=False`` keeps identity equality (for classes holding arrays, whose field-wise
    comparison has no truth value).
    """

    def wrap(c):
        return jax.tree_util.register_dataclass(dataclasses.dataclass(frozen=True, eq=eq)(c))

    return wrap if cls is None else wrap(cls)


def static(default):
    """A static field of a `pytree_dataclass` with this default."""
    return dataclasses.field(default=default, metadata={"static": True})
