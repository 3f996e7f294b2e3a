"""The ``radarviz`` console script's entry point, a module apart from the package.

Importing the command line (numpy, numba, every command's module) takes a second or more, and
a Ctrl-C in that time raised ``KeyboardInterrupt`` inside some import: a traceback of 4 to 60
lines and the status of a process killed by SIGINT. This module imports nothing at its own
import (``import radarviz`` alone loads numpy and numba), so the console script's
``from radarviz_entry import main`` is over at once, and :func:`main` turns an interrupt
during the heavy imports into the one line and exit status 130 that an interrupt during the
argument parse gets (``radarviz.viz_app.cli.main.main``).

An interrupt before :func:`main` runs is beyond the project: from the interpreter's SIGINT
handler (installed before ``site``) to the first line of :func:`main`, the process runs only
CPython's start-up (``encodings``, ``site`` and the environment's ``.pth`` files, an editable
install's path finder among them) and the installer's script wrapper. Ctrl-C there is a
traceback from those (or, earlier, the silent death of a process killed by SIGINT).
"""

from __future__ import annotations

import sys

#: Standard error's line when Ctrl-C arrives before a command has started.
STARTUP_INTERRUPTED = "radarviz: interrupted while starting, nothing done"
#: The shell's exit status for a command ended by SIGINT (128 + 2).
EXIT_INTERRUPTED = 130


def main() -> int:
    """Import the command line and run it; an interrupt during the import is one line, 130.

    The interrupt is noted by a SIGINT handler of its own for the time of the import, and any
    error the import ends in after one is the interrupt's: Ctrl-C inside an extension
    module's initialisation (numpy's ``_multiarray_umath``) can leave it half made, so that
    what comes out is not ``KeyboardInterrupt`` but the ``ImportError`` of its second load
    ("cannot load module more than once per process").
    """
    # _signal, the C module under ``signal``: loaded with the interpreter, so taking it costs
    # no import (``signal`` builds its enums in Python, an import Ctrl-C can interrupt).
    import _signal

    state = {"importing": True, "interrupted": False}

    def on_sigint(signum: int, frame: object) -> None:
        state["interrupted"] = True
        if state["importing"]:
            raise KeyboardInterrupt

    def unraisable(info: sys.UnraisableHookArgs) -> None:
        # An interrupt raised inside a callback the import machinery runs (a module lock's
        # weak reference) cannot propagate: it is noted above; the rest are shown as before.
        if not (state["interrupted"] and issubclass(info.exc_type, KeyboardInterrupt)):
            hook(info)

    hook = sys.unraisablehook
    previous = _signal.getsignal(_signal.SIGINT)
    ours = previous is _signal.default_int_handler  # an ignored SIGINT stays ignored
    if ours:
        sys.unraisablehook = unraisable
        _signal.signal(_signal.SIGINT, on_sigint)
    try:
        try:
            from radarviz.viz_app.cli.main import main as run
        finally:
            state["importing"] = False
    except BaseException:
        if not state["interrupted"]:
            raise
    finally:
        if ours:
            _signal.signal(_signal.SIGINT, previous)
            sys.unraisablehook = hook
    if state["interrupted"]:
        print(STARTUP_INTERRUPTED, file=sys.stderr)
        return EXIT_INTERRUPTED
    return run()


if __name__ == "__main__":
    sys.exit(main())
