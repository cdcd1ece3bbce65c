"""Provenance and table writing shared by the experiment scripts.

Every table in `results/` carries the machine, library versions, git SHA and the config that
produced it, so that a number can be traced to the run that printed it.
"""

from __future__ import annotations

import csv
import datetime as _dt
import importlib.metadata as _md
import json
import os
import platform
import subprocess
from collections.abc import Mapping, Sequence
from typing import Any

_PACKAGES = (
    "jax",
    "jaxlib",
    "optimistix",
    "equinox",
    "lineax",
    "numpy",
    "scipy",
    "opencv-python-headless",
    "scikit-image",
)


def cpu_name() -> str:
    """The CPU model name (from /proc/cpuinfo where available)."""
    try:
        with open("/proc/cpuinfo", encoding="utf-8") as f:
            for line in f:
                if line.startswith("model name"):
                    return line.split(":", 1)[1].strip()
    except OSError:
        pass
    return platform.processor() or "unknown CPU"


#: The paths whose uncommitted changes make a result's code differ from its commit. Changes
#: elsewhere (results/, README, notebooks) do not change what a script computes.
CODE_PATHS = ("cslx", "experiments", "pyproject.toml")


def git_sha(root: str | None = None) -> str:
    """HEAD's short SHA, with `-dirty` when `CODE_PATHS` have uncommitted changes; or 'unknown'.

    A result produced while only `results/` or the README differ from HEAD is still the
    output of HEAD's code, so it names the clean commit.
    """
    root = root or os.path.dirname(os.path.dirname(os.path.abspath(__file__)))
    try:
        sha = subprocess.run(
            ["git", "rev-parse", "--short", "HEAD"],
            cwd=root,
            capture_output=True,
            text=True,
            check=True,
        ).stdout.strip()
        dirty = subprocess.run(
            ["git", "status", "--porcelain", "--untracked-files=no", "--", *CODE_PATHS],
            cwd=root,
            capture_output=True,
            text=True,
        ).stdout.strip()
        return sha + ("-dirty" if dirty else "")
    except (OSError, subprocess.CalledProcessError):
        return "unknown"


def provenance(config: Mapping[str, Any] | None = None) -> dict[str, Any]:
    """Machine, devices, versions, git SHA, date and the run's config."""
    import jax

    versions = {}
    for p in _PACKAGES:
        try:
            versions[p] = _md.version(p)
        except _md.PackageNotFoundError:
            pass
    devices = [f"{d.platform}:{getattr(d, 'device_kind', '')}" for d in jax.devices()]
    return {
        "date": _dt.datetime.now(_dt.UTC).isoformat(timespec="seconds"),
        "git": git_sha(),
        "cpu": cpu_name(),
        "cores": os.cpu_count(),
        "devices": devices,
        "python": platform.python_version(),
        "versions": versions,
        "threads": {k: os.environ[k] for k in ("XLA_FLAGS", "OMP_NUM_THREADS") if k in os.environ},
        "config": dict(config or {}),
    }


def provenance_md(prov: Mapping[str, Any]) -> str:
    """A short Markdown block describing where and how a result was produced."""
    v = ", ".join(f"{k} {val}" for k, val in prov["versions"].items())
    devices = ", ".join(prov["devices"])
    lines = [
        f"- produced {prov['date']} at git `{prov['git']}`",
        f"- machine: {prov['cpu']}, {prov['cores']} cores; JAX devices: {devices}",
        f"- Python {prov['python']}; {v}",
        f"- config: `{json.dumps(prov['config'], sort_keys=True, default=str)}`",
    ]
    return "\n".join(lines) + "\n"


def write_csv(path: str, rows: Sequence[Mapping[str, Any]], fields: Sequence[str] | None = None):
    """Write rows of dicts as CSV (columns in the order of `fields` or of the first row).

    Written atomically (`cslx.files.atomic_write`): a failure leaves the previous file intact.
    """
    from .files import atomic_write

    fields = list(fields or (rows[0].keys() if rows else []))
    os.makedirs(os.path.dirname(os.path.abspath(path)), exist_ok=True)
    with atomic_write(path, "w", newline="", encoding="utf-8") as f:
        w = csv.DictWriter(f, fieldnames=fields, extrasaction="ignore")
        w.writeheader()
        for r in rows:
            w.writerow({k: _fmt(r.get(k)) for k in fields})


def _fmt(x):
    if isinstance(x, float):
        return f"{x:.6g}"
    return x


def md_table(
    rows: Sequence[Mapping[str, Any]], fields: Sequence[str], floatfmt: str = ".3f"
) -> str:
    """Rows of dicts as a GitHub Markdown table."""

    def cell(x):
        if isinstance(x, float):
            return format(x, floatfmt)
        return "" if x is None else str(x)

    out = ["| " + " | ".join(fields) + " |", "|" + "---|" * len(fields)]
    out += ["| " + " | ".join(cell(r.get(k)) for k in fields) + " |" for r in rows]
    return "\n".join(out) + "\n"
