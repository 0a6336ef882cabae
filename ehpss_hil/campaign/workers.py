"""What every campaign executor shares: the callback each finished run goes to, the default
number of local workers, how long a Dask scheduler may take to answer, and the :class:`Tally`
of the workers lost and the runs retried.

The local pool (:mod:`.localpool`) and Dask (:mod:`.cluster`) both import it; neither imports
the other, nor :mod:`.executors`, which picks one of them.
"""

from __future__ import annotations

import os
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any

OnResult = Callable[[dict[str, Any]], None]

#: how long to wait for a Dask scheduler to answer (s; ``campaign --connect-timeout``): a closed
#: port is retried until then
CONNECT_TIMEOUT_S = 30.0
#: the range ``--connect-timeout`` accepts (s)
CONNECT_TIMEOUT_RANGE_S = (0.1, 3600.0)


def default_workers() -> int:
    """Local worker processes by default: every core."""
    return os.cpu_count() or 1


@dataclass
class Tally:
    """What went wrong under the runs in one session: the workers lost (their addresses) and the
    indices of the runs executed again (a lost worker's runs; a failed run submitted again).
    Written by the executor's threads, read by the progress line and the summary."""

    lost_workers: list[str] = field(default_factory=list)
    retried: list[int] = field(default_factory=list)
    _lock: threading.Lock = field(default_factory=threading.Lock, repr=False, compare=False)

    def lost(self, worker: str, runs: Sequence[int]) -> None:
        """``worker`` was lost while processing ``runs`` (which run again elsewhere)."""
        with self._lock:
            self.lost_workers.append(worker)
            self.retried.extend(runs)

    def retry(self, index: int) -> None:
        """Run ``index`` failed and is submitted again."""
        with self._lock:
            self.retried.append(index)

    def counts(self) -> tuple[int, int]:
        """(workers lost, runs retried)."""
        with self._lock:
            return len(self.lost_workers), len(self.retried)

    def text(self) -> str:
        """``1 worker lost, 2 runs retried`` (empty when nothing went wrong)."""
        return self._describe(detail=False)

    def detail(self) -> str:
        """``1 worker lost (tcp://…), 2 runs retried (runs 3, 7)`` (empty: nothing went wrong)."""
        return self._describe(detail=True)

    def _describe(self, detail: bool) -> str:
        with self._lock:
            lost, retried = list(self.lost_workers), list(self.retried)
        if not lost and not retried:
            return ""
        workers = f"{len(lost)} worker{'' if len(lost) == 1 else 's'} lost"
        runs = f"{len(retried)} run{'' if len(retried) == 1 else 's'} retried"
        if detail and lost:
            workers += f" ({', '.join(lost)})"
        if detail and retried:
            runs += f" (runs {', '.join(str(i) for i in sorted(set(retried)))})"
        return f"{workers}, {runs}"
