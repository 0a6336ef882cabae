"""The project's one exception hierarchy.

Every error raised on purpose derives from :class:`EhpssError`; each child also inherits the
matching builtin so callers may catch either (the pattern of python-can's ``CanError``).
"""

from __future__ import annotations

import errno
import os
import reprlib
import resource  # loaded now: under a small ``ulimit -v`` it may not load when memory runs out
import sys
from collections.abc import Callable
from typing import Any

from .interrupt import INTERRUPTED_EXIT, ended_by_interrupt, release_startup
from .limits import MAX_MESSAGE_CHARS, MAX_SHOWN_CHARS

_SHOW = reprlib.Repr()
_SHOW.maxstring = MAX_SHOWN_CHARS
_SHOW.maxother = MAX_SHOWN_CHARS
_SHOW.maxlist = _SHOW.maxtuple = _SHOW.maxset = _SHOW.maxdict = 4
_SHOW.maxlevel = 2


def one_line(text: str, limit: int = MAX_MESSAGE_CHARS) -> str:
    """``text`` on one line (control characters escaped), cut to ``limit`` characters."""
    if not text.isprintable():
        text = "".join(c if c.isprintable() else repr(c)[1:-1] for c in text)
    return text if len(text) <= limit else text[: limit - 1] + "…"


def show(value: Any) -> str:
    """A short ``repr`` of a value from an input file, for an error message (``reprlib``-cut
    to about :data:`~ehpss_hil.limits.MAX_SHOWN_CHARS` characters, one line)."""
    if isinstance(value, int) and not isinstance(value, bool) and value.bit_length() > 192:
        return f"an integer of {value.bit_length()} bits"  # repr() refuses > 4300 digits
    try:
        text = _SHOW.repr(value)
    except (ValueError, RecursionError):
        text = f"a {type(value).__name__}"
    return one_line(text, 2 * MAX_SHOWN_CHARS)


class EhpssError(Exception):
    """Root of all ehpss-hil errors."""

    #: process exit code the CLI uses for this error class
    exit_code: int = 1


class ConfigError(EhpssError, ValueError):
    """A configuration or scenario file is invalid.

    The message names the file, the key path (``events[2].k_loe``) and what was expected.
    """

    exit_code = 2

    def __init__(self, source: str, key_path: str, reason: str) -> None:
        self.source = source
        self.key_path = key_path
        self.reason = reason
        where = f"{source}: " if source else ""
        key = key_path if key_path else "<top level>"
        super().__init__(one_line(f"{where}{key}: {reason}"))

    def __reduce__(self) -> tuple[type[ConfigError], tuple[str, str, str]]:
        """Pickled with its three fields: a worker process's error reaches the parent intact
        (the default pickling calls ``__init__`` with the message alone and fails there)."""
        return (type(self), (self.source, self.key_path, self.reason))


class FrameError(EhpssError, ValueError):
    """A CAN frame cannot be encoded or decoded (malformed, unknown, implausible)."""


class FrameIdError(FrameError):
    """The configured ID layout (``ids.id_base``, node ids) puts a frame outside the 11-bit
    range or on another frame's ID."""


class BusUnavailableError(EhpssError, OSError):
    """The configured CAN interface/channel cannot be opened (missing vcan0, no AF_CAN, ...)."""

    exit_code = 3


class OutputError(EhpssError, OSError):
    """An output file or folder cannot be written (read-only, full) or is not ours to replace
    (a non-empty folder another program wrote)."""

    exit_code = 2


class NodeError(EhpssError, OSError):
    """A CANopen node at start-up is missing (no SDO answer, no heartbeat) or is not the device
    the config names (device type, state): the controller cannot drive it."""

    exit_code = 3


class BringupRefused(EhpssError, RuntimeError):
    """A bring-up check found the valve not as the controller expects it (a reversed polarity,
    a spool far off null, no motion, sensors missing): do not enable it (``ehpss-hil bringup``)."""

    exit_code = 3


class InjectError(EhpssError, ValueError):
    """The monitor refuses a fault injection request (off, unknown kind, bad value, not sent)."""

    exit_code = 2


class CaptureError(EhpssError, ValueError):
    """The monitor refuses a triggered-capture request (bad trigger, span, field or level)."""

    exit_code = 2


class ServeError(EhpssError, OSError):
    """The monitor's web server cannot listen where it was told (port taken, bad address)."""

    exit_code = 2


class MissingExtraError(EhpssError, ImportError):
    """A command needs an optional install (an extra: campaign, monitor, plot) that is not
    there; the message names the ``pip install`` that brings it."""

    exit_code = 2


class ProcessFailedError(EhpssError):
    """A child process of ``ehpss-hil run`` ended badly; the exit code is the child's when it
    has a meaning of its own (2 bad config or output, 3 missing interface), else 1."""

    def __init__(self, message: str, child_exit_code: int | None = None) -> None:
        super().__init__(message)
        self.exit_code = child_exit_code if child_exit_code in (2, 3) else 1


class ModelError(EhpssError, ArithmeticError):
    """A physical/controller model cannot be built (unstable, singular, bad dimensions)."""


class PlantStepError(EhpssError, RuntimeError):
    """The emulated plant cannot advance (an FMU's step failed or returned a non-finite value):
    the message names the plant, the FMI function, its status and the time. The run stops
    (the emulator: fail-safe, no more sensor frames); the input was loadable, so exit 1."""


class ControlTimeoutError(EhpssError, TimeoutError):
    """Sensor or command data went stale for longer than the configured watchdog allows."""


#: exit code of a program that ran out of memory (the environment's limit, not bad input)
EXIT_OUT_OF_MEMORY = 1
#: exit code of a program that ran out of file descriptors (``ulimit -n``, not bad input)
EXIT_OUT_OF_FILES = 1
#: the address space a program needs with a multi-threaded OpenBLAS (bytes): `ehpss-hil sim`
#: peaks at 287 MB with 2 or more BLAS threads (205 MB with one), plus headroom. Below it, where
#: the first allocation fails is chance (a MemoryError, a library's parse error, or a library
#: retrying for ever), so the program refuses at once.
THREADED_BLAS_MIN_ADDRESS_SPACE = 512 * 2**20


def run_console(prog: str, fn: Callable[[], int]) -> int:
    """Run a console command's body: an :class:`EhpssError` becomes one line on stderr
    (``<prog>: error: …``) and its class's exit code; Ctrl-C exits 130 (whatever error it
    caused: :func:`~ehpss_hil.interrupt.ended_by_interrupt`); running out of memory
    (a small ``ulimit -v``) is one line naming the limit, exit :data:`EXIT_OUT_OF_MEMORY`, and
    so is a multi-threaded OpenBLAS under an address-space limit it cannot fit, before anything
    runs; running out of file descriptors (``ulimit -n``) is one line naming the limit, exit
    :data:`EXIT_OUT_OF_FILES`."""
    if _threaded_blas_does_not_fit():
        print(f"{prog}: error: out of memory (refused at start){_memory_limits()}", file=sys.stderr)
        return EXIT_OUT_OF_MEMORY
    try:
        release_startup()  # a Ctrl-C from here on is a KeyboardInterrupt, exit 130 below
        try:
            return fn()
        except BaseException as exc:
            if ended_by_interrupt(exc):
                return INTERRUPTED_EXIT
            raise
    except EhpssError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except MemoryError as exc:
        what = f" ({one_line(str(exc))})" if str(exc) else ""
        print(f"{prog}: error: out of memory{what}{_memory_limits()}", file=sys.stderr)
        return EXIT_OUT_OF_MEMORY
    except OSError as exc:  # the environment's limit on open files (ulimit -n), not bad input
        if exc.errno not in (errno.EMFILE, errno.ENFILE):
            raise
        print(f"{prog}: error: {exc.strerror or exc}{_file_limits()}", file=sys.stderr)
        return EXIT_OUT_OF_FILES
    except ImportError as exc:  # a shared library that no longer fits the address space
        if "failed to map segment" not in str(exc):
            raise
        print(f"{prog}: error: out of memory ({one_line(str(exc))}){_memory_limits()}", file=sys.stderr)
        return EXIT_OUT_OF_MEMORY


def _file_limits() -> str:
    """``; open-file limit 8 (ulimit -n)`` — what bounds the open files here, or empty."""
    soft, _ = resource.getrlimit(resource.RLIMIT_NOFILE)
    return "" if soft == resource.RLIM_INFINITY else f"; open-file limit {soft} (ulimit -n)"


def _threaded_blas_does_not_fit() -> bool:
    """``OPENBLAS_NUM_THREADS`` above 1 (the user's choice) with an address-space limit below
    :data:`THREADED_BLAS_MIN_ADDRESS_SPACE`."""
    try:
        threads = int(os.environ.get("OPENBLAS_NUM_THREADS", "1"))
    except ValueError:
        return False
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    return threads > 1 and soft != resource.RLIM_INFINITY and soft < THREADED_BLAS_MIN_ADDRESS_SPACE


def _memory_limits() -> str:
    """``; address-space limit 195 MiB (ulimit -v), OPENBLAS_NUM_THREADS=8`` — what bounds the
    memory here, or empty."""
    soft, _ = resource.getrlimit(resource.RLIMIT_AS)
    parts = (
        [] if soft == resource.RLIM_INFINITY else [f"address-space limit {soft / 2**20:.0f} MiB (ulimit -v)"]
    )
    threads = os.environ.get("OPENBLAS_NUM_THREADS")
    if threads and threads != "1":
        parts.append(f"OPENBLAS_NUM_THREADS={threads} (each BLAS thread reserves its own buffers)")
    return "; " + ", ".join(parts) if parts else ""


class ClusterError(EhpssError, ConnectionError):
    """A compute cluster (the Dask scheduler of ``ehpss-hil campaign --scheduler``) cannot be
    reached or used."""

    exit_code = 3


class WorkerLostError(EhpssError, RuntimeError):
    """A campaign run kept losing its local worker process (killed from outside: the OOM killer,
    ``kill -9``) more often than the campaign allows; the runs finished before are kept."""
