"""Packages that import their submodules on first use.

`cslx.runtime` and `cslx.segmentation` re-export their public names, but importing either
package loads no submodule: the robot's start-up from the compile cache imports only what a
frame needs (issue 13, start-up ≤ 1.5 s; tests/test_architecture.py checks it).
"""

from __future__ import annotations

import importlib
import importlib.util
from collections.abc import Callable, Mapping
from typing import Any

__all__ = ["lazy_attributes"]


def lazy_attributes(
    package: str, namespace: dict[str, Any], owners: Mapping[str, str | None]
) -> tuple[Callable[[str], Any], Callable[[], list[str]]]:
    """The module-level ``__getattr__`` and ``__dir__`` (PEP 562) of a lazy package.

    Args:
        package: the package's ``__name__``.
        namespace: the package's ``globals()``; a name, once resolved, is stored there, so
            later look-ups cost nothing.
        owners: public name → the submodule (relative to ``package``) that defines it, or
            None where the name is that submodule itself.

    Any other name that is a submodule resolves to that submodule (``cslx.runtime.pipeline``
    works without an import statement); everything else raises `AttributeError`.
    """

    def getattr_(name: str) -> Any:
        if name in owners:
            owner = owners[name]
            module = importlib.import_module(f"{package}.{owner or name}")
            value = module if owner is None else getattr(module, name)
            namespace[name] = value
            return value
        if not name.startswith("_") and importlib.util.find_spec(f"{package}.{name}"):
            return importlib.import_module(f"{package}.{name}")
        raise AttributeError(f"module {package!r} has no attribute {name!r}")

    def dir_() -> list[str]:
        return sorted({*namespace, *owners})

    return getattr_, dir_
