"""The architecture holds: one public/private line, runtime free of simulation, small files.

These checks read the source (AST), so they fail the moment a change crosses a line:

- nothing imports another subpackage's private (`_`-prefixed) names or modules, by import or
  by attribute access on an imported module; tests in `tests/<subpackage>/` may reach into
  the privates of `cslx.<subpackage>`, the code they test;
- `cslx.runtime` never imports `cslx.sim` (a robot has no renderer installed);
- no module in `cslx/` is longer than 600 lines;
- `import cslx` and `import cslx.cli` do not import JAX, and `cslx.segmentation.med` is a module;
- every Markdown file cited in the code, the README or the notebooks exists in the repository.
"""

from __future__ import annotations

import ast
import json
import re
import subprocess
import sys
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]
PACKAGE = ROOT / "cslx"
SUBPACKAGES = sorted(p.name for p in PACKAGE.iterdir() if (p / "__init__.py").exists())


def _sources() -> list[tuple[Path, str]]:
    out = []
    for folder in ("cslx", "tests", "experiments"):
        for path in sorted((ROOT / folder).rglob("*.py")):
            out.append((path, path.read_text()))
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        cells = json.loads(path.read_text())["cells"]
        code = "\n".join("".join(c["source"]) for c in cells if c["cell_type"] == "code")
        code = "\n".join(
            line for line in code.splitlines() if not line.lstrip().startswith(("%", "!"))
        )
        out.append((path, code))
    return out


def _module_of(path: Path) -> str | None:
    """Dotted module name of a file inside cslx/, else None."""
    try:
        rel = path.relative_to(ROOT)
    except ValueError:
        return None
    if rel.parts[0] != "cslx" or path.suffix != ".py":
        return None
    parts = list(rel.with_suffix("").parts)
    if parts[-1] == "__init__":
        parts.pop()
    return ".".join(parts)


def _owner(path: Path) -> str | None:
    """The cslx subpackage a file belongs to (code in it, or its tests), else None."""
    rel = path.relative_to(ROOT).parts
    if rel[0] == "cslx" and len(rel) > 2:
        return rel[1]
    if rel[0] == "tests" and len(rel) > 2 and rel[1] in SUBPACKAGES:
        return rel[1]
    return None


def _resolve(node: ast.ImportFrom, module: str | None, is_package: bool) -> str:
    if not node.level:
        return node.module or ""
    assert module is not None, "relative import outside the package"
    base = module.split(".")
    if not is_package:
        base = base[:-1]
    base = base[: len(base) - (node.level - 1)]
    return ".".join(base + ([node.module] if node.module else []))


def _subpackage(dotted: str) -> str | None:
    parts = dotted.split(".")
    return parts[1] if len(parts) > 1 and parts[0] == "cslx" else None


def _private(dotted: str) -> bool:
    return any(p.startswith("_") and not p.startswith("__") for p in dotted.split("."))


def _violations():
    found = []
    for path, code in _sources():
        tree = ast.parse(code)
        module = _module_of(path)
        owner = _owner(path)
        is_package = path.name == "__init__.py"
        aliases: dict[str, str] = {}
        for node in ast.walk(tree):
            targets = []
            if isinstance(node, ast.ImportFrom):
                base = _resolve(node, module, is_package)
                if not base.startswith("cslx"):
                    continue
                for a in node.names:
                    targets.append(f"{base}.{a.name}")
                    aliases[a.asname or a.name] = f"{base}.{a.name}"
            elif isinstance(node, ast.Import):
                for a in node.names:
                    if a.name.startswith("cslx"):
                        targets.append(a.name)
                        aliases[a.asname or a.name.split(".")[0]] = a.name
            for target in targets:
                sub = _subpackage(target)
                if _private(target) and sub != owner:
                    found.append(f"{path.relative_to(ROOT)}:{node.lineno}: imports {target}")
        for node in ast.walk(tree):
            if (
                isinstance(node, ast.Attribute)
                and isinstance(node.value, ast.Name)
                and node.value.id in aliases
                and node.attr.startswith("_")
                and not node.attr.startswith("__")
                and _subpackage(aliases[node.value.id]) != owner
            ):
                found.append(
                    f"{path.relative_to(ROOT)}:{node.lineno}: uses "
                    f"{aliases[node.value.id]}.{node.attr}"
                )
    return found


def test_no_private_names_across_subpackages():
    assert _violations() == []


def test_runtime_never_imports_simulation():
    bad = []
    for path in sorted((PACKAGE / "runtime").rglob("*.py")):
        module = _module_of(path)
        for node in ast.walk(ast.parse(path.read_text())):
            if isinstance(node, ast.ImportFrom):
                target = _resolve(node, module, path.name == "__init__.py")
                names = [f"{target}.{a.name}" for a in node.names]
            elif isinstance(node, ast.Import):
                names = [a.name for a in node.names]
            else:
                continue
            bad += [f"{path.name}: {n}" for n in names if n.startswith("cslx.sim")]
    assert bad == []


def test_modules_are_small():
    sizes = {
        str(p.relative_to(ROOT)): len(p.read_text().splitlines()) for p in PACKAGE.rglob("*.py")
    }
    assert {k: v for k, v in sizes.items() if v > 600} == {}


def test_import_is_cheap_and_side_effect_free():
    code = (
        "import os, sys; before = dict(os.environ); import cslx, cslx.cli; "
        "assert 'jax' not in sys.modules, 'jax imported'; "
        "assert 'numpy' not in sys.modules, 'numpy imported'; "
        "assert dict(os.environ) == before, 'environment changed'; "
        "import cslx.segmentation, types; "
        "assert isinstance(cslx.segmentation.med, types.ModuleType)"
    )
    subprocess.run([sys.executable, "-c", code], check=True, cwd=ROOT)


def test_runtime_import_skips_heavy_modules():
    """The robot's start-up imports only what a cached frame needs (issue 13, start-up ≤ 1.5 s).

    optimistix and lineax (≈ 0.13 s) are needed only to trace MED or the undistortion, which a
    start-up from the compile cache never does; plotting, SciPy, OpenCV and the simulation are
    never needed by the runtime.
    """
    heavy = ["matplotlib", "scipy", "cv2", "pandas", "tqdm", "optimistix", "lineax", "cslx.sim"]
    imports = "cslx.runtime, cslx.runtime.tracker, cslx.runtime.pipeline"
    assert _loaded_after(imports, heavy) == []


def test_tracker_import_leaves_the_pipeline_unloaded():
    """A cached tracker start needs neither the pipeline nor MED/Steger (cslx.runtime.compiled)
    nor equinox (≈ 0.14 s; `cslx.pytree`) nor jaxtyping (annotations only): importing the
    tracker and the sensor must not load them (issue 13, start-up)."""
    lazy = ["cslx.runtime.pipeline", "cslx.segmentation.med", "cslx.runtime.controller"]
    lazy += ["equinox", "jaxtyping"]
    assert _loaded_after("cslx.runtime.tracker, cslx.sensor", lazy) == []


def _loaded_after(imports: str, modules: list[str]) -> list[str]:
    """Those of ``modules`` that a fresh interpreter has loaded after ``import {imports}``."""
    code = f"import sys; import {imports}; print(*(m for m in {modules!r} if m in sys.modules))"
    out = subprocess.run(
        [sys.executable, "-c", code], check=True, cwd=ROOT, capture_output=True, text=True
    )
    return out.stdout.split()


def test_cited_documents_exist():
    pattern = re.compile(r"[\w./-]*[A-Za-z0-9_-]+\.md\b")
    tracked = {p.name for p in ROOT.rglob("*.md") if ".venv" not in p.parts}
    missing = set()
    texts = [(p, c) for p, c in _sources()] + [
        (ROOT / "README.md", (ROOT / "README.md").read_text())
    ]
    for path in sorted((ROOT / "notebooks").glob("*.ipynb")):
        texts.append((path, path.read_text()))
    for path, text in texts:
        for ref in pattern.findall(text):
            name = Path(ref).name
            if name.startswith(("<", "{")) or "*" in name or name.startswith("results/"):
                continue
            if name not in tracked and not re.fullmatch(r"[a-z0-9_]+\.md", name):
                missing.add(f"{path.relative_to(ROOT)}: {ref}")
    assert missing == set()


@pytest.mark.parametrize("sub", SUBPACKAGES)
def test_subpackages_declare_their_public_names(sub):
    import importlib

    mod = importlib.import_module(f"cslx.{sub}")
    assert getattr(mod, "__all__", None), f"cslx.{sub} has no __all__"
    for name in mod.__all__:
        assert hasattr(mod, name), f"cslx.{sub}.__all__ names {name!r}, which is missing"
