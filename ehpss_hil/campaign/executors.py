"""Where campaign runs execute: local processes (:class:`LocalPool`), or Dask
(:class:`~ehpss_hil.campaign.cluster.DaskExecutor`: a scheduler's address or a LocalCluster).

Every executor takes the runs to do, a callback called in the main process with each finished
record, in completion order (the table is sorted by run index afterwards, so the order does not
matter), and a :class:`Tally` of the workers lost and the runs retried. Ctrl-C
(KeyboardInterrupt) stops the workers and propagates; what the callback got is kept.
"""

from __future__ import annotations

import ctypes
import multiprocessing as mp
import os
import signal
import threading
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from typing import Any, Protocol

from ..blas import limit_blas_threads
from .runs import RunTask, execute

OnResult = Callable[[dict[str, Any]], None]
#: prctl(2) option: the signal a process gets when its parent dies (linux/prctl.h)
PR_SET_PDEATHSIG = 1


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


class Executor(Protocol):
    """Runs campaign tasks somewhere; ``description`` says where, ``dashboard`` is a link to
    watch it (empty: none)."""

    @property
    def description(self) -> str:
        """Where the runs go (one line)."""

    dashboard: str

    def run(self, tasks: Sequence[RunTask], on_result: OnResult, tally: Tally) -> None:
        """Run every task, ``on_result`` with each record."""


def _die_with_parent(parent: int) -> None:
    """Linux: the kernel kills this process with SIGKILL when its parent dies, so a pool worker
    of a campaign killed with ``kill -9`` ends at once (not after its run, failing to send it
    back with a BrokenPipeError traceback). Elsewhere: nothing."""
    try:
        ctypes.CDLL(None, use_errno=True).prctl(PR_SET_PDEATHSIG, signal.SIGKILL)
    except (OSError, AttributeError):
        return
    if os.getppid() != parent:  # the parent died before prctl took effect
        os._exit(0)


def _worker_init(parent: int) -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the main process handles Ctrl-C
    _die_with_parent(parent)
    limit_blas_threads(1)


@dataclass
class LocalPool:
    """``workers`` local processes (1: in this process)."""

    workers: int = 1
    dashboard: str = ""

    @property
    def description(self) -> str:
        """Where the runs go."""
        return f"{max(1, self.workers)} local process(es)"

    def run(self, tasks: Sequence[RunTask], on_result: OnResult, tally: Tally | None = None) -> None:
        """Run ``tasks`` (``tally`` stays empty: a local run that fails stops the campaign)."""
        run_local(tasks, self.workers, on_result)


def run_local(tasks: Sequence[RunTask], workers: int, on_result: OnResult) -> None:
    """Run ``tasks`` on ``workers`` processes (1: in this process)."""
    limit_blas_threads(1)  # before forking: no spinning BLAS pool to inherit
    if workers <= 1 or len(tasks) <= 1:
        for t in tasks:
            on_result(execute(t))
        return
    ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    pool = ctx.Pool(min(workers, len(tasks)), initializer=_worker_init, initargs=(os.getpid(),))
    try:
        for rec in pool.imap_unordered(execute, tasks, chunksize=1):
            on_result(rec)
        pool.close()
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.join()
