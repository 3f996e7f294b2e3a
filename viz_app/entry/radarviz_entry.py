"""The ``radarviz`` console script's entry point, a module apart from the package.

Importing the command line (numpy, numba, every command's module) takes a second or more, and
a Ctrl-C in that time raised ``KeyboardInterrupt`` inside some import: a traceback of 4 to 60
lines and the status of a process killed by SIGINT. This module imports nothing at its own
import (``import radarviz`` alone loads numpy and numba), so the console script's
``from radarviz_entry import main`` is over at once, and :func:`main` turns an interrupt
during the heavy imports into the one line and exit status 130 that an interrupt during the
argument parse gets (``radarviz.viz_app.cli.main.main``).
"""

from __future__ import annotations

import sys

#: Standard error's line when Ctrl-C arrives before a command has started.
STARTUP_INTERRUPTED = "radarviz: interrupted while starting, nothing done"
#: The shell's exit status for a command ended by SIGINT (128 + 2).
EXIT_INTERRUPTED = 130


def main() -> int:
    """Import the command line and run it; an interrupt during the import is one line, 130."""
    try:
        from radarviz.viz_app.cli.main import main as run
    except KeyboardInterrupt:
        print(STARTUP_INTERRUPTED, file=sys.stderr)
        return EXIT_INTERRUPTED
    return run()


if __name__ == "__main__":
    sys.exit(main())
