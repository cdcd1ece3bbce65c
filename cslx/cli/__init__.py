"""The `cslx` command line.

Each subcommand lives in its own module in this package and defines `NAME`, `HELP`,
`add_arguments(parser)` and `run(args) -> int`. Modules import JAX lazily inside `run`, so
`cslx --help` stays fast, and check their arguments before any work.

Exit status: 0 success, 1 some input failed (reported on stderr), 2 a usage error (a bad
argument, a missing or unusable input or output path: one line saying which and what to
do), 130 interrupted. Named outputs are written atomically (`cslx.files`).
"""

from __future__ import annotations

import argparse
import importlib
import sys

__all__ = ["COMMANDS", "build_parser", "main"]

#: The subcommands, one module each in this package, in the order `--help` lists them.
COMMANDS = ("render", "calibrate", "extract", "track", "demo")


def _command_modules():
    for name in COMMANDS:
        yield importlib.import_module(f"{__name__}.{name}")


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
    # Entry point: set the process-wide settings here, before NumPy or JAX load
    # (single-threaded OpenBLAS, see `cslx.environment`).
    from ..environment import configure

    configure()
    from ..files import OutputPathError

    try:
        return int(args._run(args) or 0)
    except KeyboardInterrupt:
        print("interrupted", file=sys.stderr)
        return 130
    except OutputPathError as e:  # an output path found unwritable inside a command
        print(f"cslx {args.command}: {e}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
