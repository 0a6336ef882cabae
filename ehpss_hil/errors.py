"""The project's one exception hierarchy.

Every error raised on purpose derives from :class:`EhpssError`; each child also inherits the
matching builtin so callers may catch either (the pattern of python-can's ``CanError``).
"""

from __future__ import annotations

import sys
from collections.abc import Callable


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
        super().__init__(f"{where}{key}: {reason}")


class FrameError(EhpssError, ValueError):
    """A CAN frame cannot be encoded or decoded (malformed, unknown, implausible)."""


class BusUnavailableError(EhpssError, OSError):
    """The configured CAN interface/channel cannot be opened (missing vcan0, no AF_CAN, ...)."""

    exit_code = 3


class OutputError(EhpssError, OSError):
    """An output file or folder cannot be written (read-only, full) or is not ours to replace
    (a non-empty folder another program wrote)."""

    exit_code = 2


class ProcessFailedError(EhpssError):
    """A child process of ``ehpss-hil run`` ended badly; the exit code is the child's when it
    has a meaning of its own (2 bad config or output, 3 missing interface), else 1."""

    def __init__(self, message: str, child_exit_code: int | None = None) -> None:
        super().__init__(message)
        self.exit_code = child_exit_code if child_exit_code in (2, 3) else 1


class ModelError(EhpssError, ArithmeticError):
    """A physical/controller model cannot be built (unstable, singular, bad dimensions)."""


class ControlTimeoutError(EhpssError, TimeoutError):
    """Sensor or command data went stale for longer than the configured watchdog allows."""


def run_console(prog: str, fn: Callable[[], int]) -> int:
    """Run a console command's body: an :class:`EhpssError` becomes one line on stderr
    (``<prog>: error: …``) and its class's exit code; Ctrl-C exits 130."""
    try:
        return fn()
    except EhpssError as exc:
        print(f"{prog}: error: {exc}", file=sys.stderr)
        return exc.exit_code
    except KeyboardInterrupt:
        return 130
