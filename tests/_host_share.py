"""A writer-preferring shared/exclusive lock over two ``flock`` files, for the share of the host
each test takes (tests/conftest.py).

An exclusive holder first takes the gate exclusively (no shared taker starts after that), then
the host lock exclusively (the shared holders running have ended); a shared taker passes the gate
(shared, released at once) and holds the host lock shared. Files are opened close-on-exec, so a
child process started with ``subprocess`` never holds a share; a forked child that outlives its
test would, and the next exclusive taker then gives up at its deadline instead of hanging.
"""

from __future__ import annotations

import fcntl
import time
from collections.abc import Iterator
from contextlib import ExitStack, contextmanager
from pathlib import Path
from typing import IO

#: how often a waiting taker retries (s)
POLL_S = 0.05


def _take(stack: ExitStack, path: Path, op: int, deadline: float) -> IO[str] | None:
    """Open ``path`` on ``stack`` and flock it with ``op`` (LOCK_SH / LOCK_EX) before
    ``deadline`` (monotonic s); None when the deadline passed first."""
    f = stack.enter_context(path.open("a"))
    while True:
        try:
            fcntl.flock(f, op | fcntl.LOCK_NB)
            return f
        except BlockingIOError:
            if time.monotonic() > deadline:
                return None
            time.sleep(POLL_S)


@contextmanager
def host_share(exclusive: bool, host: Path, gate: Path, wait_s: float) -> Iterator[bool]:
    """Hold ``host`` shared, or exclusive with no shared taker let in meanwhile, for the body;
    yields whether the share was had within ``wait_s`` (s) (the body runs either way)."""
    deadline = time.monotonic() + wait_s
    op = fcntl.LOCK_EX if exclusive else fcntl.LOCK_SH
    with ExitStack() as stack:
        passed = _take(stack, gate, op, deadline)
        held = _take(stack, host, op, deadline) if passed is not None else None
        if passed is not None and not exclusive:
            fcntl.flock(passed, fcntl.LOCK_UN)
        yield held is not None
