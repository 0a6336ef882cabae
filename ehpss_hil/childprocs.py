"""The child processes of ``ehpss-hil run``: start one with its output in the run directory,
stop it, wait for a start-up line, read its one-line error."""

from __future__ import annotations

import signal
import subprocess
import time
from pathlib import Path

from . import PROJECT_ROOT
from .errors import EhpssError, ProcessFailedError


def spawn(argv: list[str], prefix: list[str], out: Path, name: str) -> subprocess.Popen[bytes]:
    """Start ``prefix + argv`` in the project directory, its stdout and stderr to
    ``out/<name>.out``."""
    with open(out / f"{name}.out", "wb") as stdout:  # the child keeps its own descriptor
        return subprocess.Popen(
            [*prefix, *argv],
            stdout=stdout,
            stderr=subprocess.STDOUT,
            stdin=subprocess.DEVNULL,
            cwd=PROJECT_ROOT,
        )


def stop(proc: subprocess.Popen[bytes], timeout_s: float = 10.0) -> int | None:
    """SIGTERM, then SIGKILL after ``timeout_s`` (s); the exit code."""
    if proc.poll() is None:
        proc.send_signal(signal.SIGTERM)
        try:
            proc.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            proc.kill()
            proc.wait()
    return proc.returncode


def wait_for_line(
    path: Path, needle: str, timeout_s: float, procs: dict[str, subprocess.Popen[bytes]]
) -> None:
    """Wait until ``needle`` appears in the growing file ``path`` (e.g. the controller's
    heartbeat in the bus log: the controller is on the bus and the logger hears it)."""
    end = time.monotonic() + timeout_s
    while time.monotonic() < end:
        if path.exists() and needle in path.read_text(errors="replace"):
            return
        dead = {n: p.returncode for n, p in procs.items() if p.poll() is not None}
        if dead:
            name, code = next(iter(dead.items()))
            raise ProcessFailedError(
                f"{name} ended during start-up (exit {code}): {last_line(path.parent / f'{name}.out')}", code
            )
        time.sleep(0.05)
    raise EhpssError(f"start-up timed out: {needle!r} not seen in {path} after {timeout_s:g} s")


def last_line(path: Path) -> str:
    """The last non-empty line of a process's output (its one-line error), or a pointer to it."""
    try:
        lines = [ln for ln in path.read_text(errors="replace").splitlines() if ln.strip()]
    except OSError:
        lines = []
    return lines[-1].strip() if lines else f"no output (see {path})"
