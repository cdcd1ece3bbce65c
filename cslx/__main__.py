"""`python -m cslx …` runs the `cslx` command (the same as the installed script)."""

import sys

from cslx.cli import main

if __name__ == "__main__":
    sys.exit(main())
