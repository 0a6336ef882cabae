"""Ctrl-C while one of the programs starts: exit 130 at once, never a traceback.

Python turns SIGINT into KeyboardInterrupt from early in its own start-up on. One that lands in
the imports before a command's body runs under :func:`ehpss_hil.errors.run_console` (which turns
it into exit 130) would print a traceback. ``import ehpss_hil`` calls :func:`guard_startup` before
anything else: in a process started as one of the programs (the ``ehpss-hil`` and
``firmware-sim`` console scripts, ``python -m`` of their modules) SIGINT then ends the process
with exit 130 (nothing is open or written yet). :func:`release_startup`, called by
``run_console``, gives Python's KeyboardInterrupt back, noting that SIGINT came: an extension
module interrupted while it initialises may raise another error instead (``TypeError`` from
``_ssl``), and :func:`ended_by_interrupt` tells ``run_console`` that it ends the command all the
same. Anyone else who imports the package (a
library user, a notebook, a test) keeps Python's handler. What runs before the package is
imported (CPython's own start-up, ``site`` and its ``.pth`` files, the console script's lookup
of ``ehpss_hil.cli``) is out of a package's reach.

This module imports only what the interpreter has loaded before it (``os``, ``sys``) and the
built-in ``_signal``: it runs before anything else of the package, unguarded until it is loaded.
"""

from __future__ import annotations

# the C module under ``signal``: ``import signal`` builds its enums (milliseconds unguarded)
import _signal  # type: ignore[import-not-found]
import os
import sys

TYPE_CHECKING = False  # not typing's: importing typing would lengthen the unguarded start
if TYPE_CHECKING:
    from collections.abc import Callable
    from types import FrameType
    from typing import Any

#: exit code after Ctrl-C (the shell's 128 + SIGINT)
INTERRUPTED_EXIT = 130
#: the console scripts (``[project.scripts]``) whose start-up is guarded
PROGRAMS = frozenset({"ehpss-hil", "firmware-sim"})
#: the modules whose ``python -m`` start-up is guarded
PROGRAM_MODULES = frozenset({"ehpss_hil.cli", "firmware_sim.cli"})
#: the interpreter's options whose value is the next word (``python -X importtime …``)
_OPTIONS_WITH_VALUE = frozenset({"-W", "-X", "--check-hash-based-pycs"})
#: whether SIGINT came since :func:`release_startup` (written by the signal handler)
_STATE = {"interrupted": False}
#: a KeyboardInterrupt that would land in the import system is raised this much later (s)
IMPORT_RETRY_S = 0.001
#: the import system's module: an exception raised in its callbacks (a module lock's weakref
#: callback) is printed as "Exception ignored" with a traceback, and the program goes on
_IMPORT_SYSTEM = "importlib._bootstrap"


def _exit_interrupted(signum: int, frame: FrameType | None) -> None:
    """SIGINT during start-up: leave now, with the exit code of Ctrl-C."""
    os._exit(INTERRUPTED_EXIT)


def _raise_interrupt(signum: int, frame: FrameType | None) -> None:
    """SIGINT while a command runs: noted, then Python's KeyboardInterrupt — not inside the
    import system, where the interpreter would print it as ignored and carry on: from there it
    is raised :data:`IMPORT_RETRY_S` later (SIGALRM, this handler again)."""
    _STATE["interrupted"] = True
    if frame is not None and frame.f_globals.get("__name__") == _IMPORT_SYSTEM:
        _signal.signal(_signal.SIGALRM, _raise_interrupt)
        _signal.setitimer(_signal.ITIMER_REAL, IMPORT_RETRY_S)
        return
    _signal.default_int_handler(signum, frame)


def ended_by_interrupt(exc: BaseException) -> bool:
    """``exc`` is a KeyboardInterrupt, or came after SIGINT did (see the module docstring).

    Then CPython's mark of an unhandled KeyboardInterrupt is cleared too: CPython 3.11 sets it
    when a KeyboardInterrupt leaves an ``exec`` of a string (dataclasses build their methods so,
    in every import that defines one) even if it is caught later, and then ends the process with
    SIGINT instead of its exit code; each ``exec`` of a string clears it first."""
    if not isinstance(exc, KeyboardInterrupt) and not _STATE["interrupted"]:
        return False
    exec("")  # clears the mark: see the docstring
    return True


def started_as_program(argv: list[str] | None = None) -> bool:
    """This process was started as one of :data:`PROGRAMS` or as ``python -m`` of one of
    :data:`PROGRAM_MODULES` (``argv``: the interpreter's own command line, ``sys.orig_argv``)."""
    args = list(getattr(sys, "orig_argv", sys.argv)) if argv is None else argv
    rest = iter(args[1:])
    for a in rest:
        if a == "-m":
            return next(rest, "") in PROGRAM_MODULES
        if a in _OPTIONS_WITH_VALUE:
            next(rest, "")
        elif a == "-c" or a == "-":
            return False
        elif not a.startswith("-"):
            return os.path.basename(a) in PROGRAMS
    return False


def guard_startup() -> None:
    """In a program's process, with Python's own SIGINT handler in place: SIGINT exits
    :data:`INTERRUPTED_EXIT` until :func:`release_startup`. Otherwise nothing."""
    if _signal.getsignal(_signal.SIGINT) is _signal.default_int_handler and started_as_program():
        _set(_exit_interrupted)


def release_startup() -> None:
    """KeyboardInterrupt on SIGINT again (noted for :func:`ended_by_interrupt`), if
    :func:`guard_startup` had replaced Python's handler."""
    if _signal.getsignal(_signal.SIGINT) is _exit_interrupted:
        _set(_raise_interrupt)


def _set(handler: Callable[[int, FrameType | None], Any]) -> None:
    try:
        _signal.signal(_signal.SIGINT, handler)
    except ValueError:  # not the main thread: only the main thread sets handlers
        return
