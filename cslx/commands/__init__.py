"""Subcommands of the `cslx` command line, one module each (see `cslx.cli`)."""
