"""The `cslx` command line.

Each subcommand lives in its own module under `cslx/commands/` and defines `NAME`, `HELP`,
`add_arguments(parser)` and `run(args) -> int`. Modules import JAX lazily inside `run`, so
`cslx --help` stays fast.
"""

from __future__ import annotations

import argparse
import importlib
import os
import pkgutil
import sys

# OpenBLAS's threaded Cholesky (the MED Toeplitz solve for L > 256) was 100–1000× slower than
# single-threaded on a loaded 2-core machine; XLA does its own threading. Set before NumPy loads.
os.environ.setdefault("OPENBLAS_NUM_THREADS", "1")

from . import commands as _commands


def _command_modules():
    for info in sorted(pkgutil.iter_modules(_commands.__path__), key=lambda m: m.name):
        if info.name.startswith("_"):
            continue
        yield importlib.import_module(f"{_commands.__name__}.{info.name}")


def build_parser() -> argparse.ArgumentParser:
    parser = argparse.ArgumentParser(
        prog="cslx",
        description="Cross structured-light stripe sensing for weld-tracking robots.",
    )
    sub = parser.add_subparsers(dest="command", metavar="COMMAND", required=True)
    for mod in _command_modules():
        p = sub.add_parser(mod.NAME, help=mod.HELP, description=mod.__doc__)
        mod.add_arguments(p)
        p.set_defaults(_run=mod.run)
    return parser


def main(argv: list[str] | None = None) -> int:
    parser = build_parser()
    args = parser.parse_args(argv)
    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130


if __name__ == "__main__":
    sys.exit(main())
