"""Campaign runs on local worker processes: a ``concurrent.futures.ProcessPoolExecutor``
(forked workers, one BLAS thread each), or this process for one worker.

At most one run per worker is in flight, so the runs in flight are exactly those a worker was
given. A worker lost (killed from outside: the OOM killer, ``kill -9``) breaks the pool
(``BrokenProcessPool`` on every run in flight): the pool is built again and those runs are
submitted again, counted in the :class:`~.workers.Tally` as a lost worker and retried runs, as
Dask does for a lost worker. A run that was in flight when :data:`LOSSES_PER_ATTEMPT` workers
died, or that raises, has failed one attempt; ``retries`` more attempts are made, then the
campaign stops with the run's own error (:class:`~ehpss_hil.errors.WorkerLostError` for the
lost workers). Ctrl-C (KeyboardInterrupt) ends the workers at once and propagates. The runs'
results do not depend on where or how often they ran.
"""

from __future__ import annotations

import ctypes
import multiprocessing as mp
import os
import signal
from collections import deque
from collections.abc import Sequence
from concurrent.futures import FIRST_COMPLETED, Future, ProcessPoolExecutor, wait
from concurrent.futures.process import BrokenProcessPool
from dataclasses import dataclass
from multiprocessing.process import BaseProcess
from typing import Any

from ..blas import limit_blas_threads
from ..errors import WorkerLostError
from .runs import RunTask, execute
from .workers import OnResult, Tally

#: prctl(2) option: the signal a process gets when its parent dies (linux/prctl.h)
PR_SET_PDEATHSIG = 1
#: workers that may die while a run is in flight before that attempt of it counts as failed
#: (as Dask's ``distributed.scheduler.allowed-failures``, whose default is 3)
LOSSES_PER_ATTEMPT = 3


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
    """``workers`` local processes (1: in this process); a run that fails is run again up to
    ``retries`` times."""

    workers: int = 1
    retries: int = 0
    dashboard: str = ""

    @property
    def description(self) -> str:
        """Where the runs go."""
        return f"{max(1, self.workers)} local process(es)"

    def run(self, tasks: Sequence[RunTask], on_result: OnResult, tally: Tally | None = None) -> None:
        """Run ``tasks``; ``tally`` gets the lost workers and the retried runs."""
        run_local(tasks, self.workers, on_result, tally, self.retries)


def run_local(
    tasks: Sequence[RunTask], workers: int, on_result: OnResult, tally: Tally | None = None, retries: int = 0
) -> None:
    """Run ``tasks`` on ``workers`` processes (1: in this process), ``on_result`` with each
    record in completion order; a run that fails is run again up to ``retries`` times."""
    limit_blas_threads(1)  # before forking: no spinning BLAS pool to inherit
    tally = tally if tally is not None else Tally()
    if workers <= 1 or len(tasks) <= 1:
        for t in tasks:
            on_result(_in_process(t, retries, tally))
        return
    _Pool(min(workers, len(tasks)), retries, tally).run(tasks, on_result)


def _in_process(task: RunTask, retries: int, tally: Tally) -> dict[str, Any]:
    """``execute(task)`` here, again up to ``retries`` times when it raises."""
    for _ in range(retries):
        try:
            return execute(task)
        except Exception:
            tally.retry(task.index)
    return execute(task)


@dataclass
class _Run:
    """A run to do: its task, the attempts failed so far, the workers lost under this attempt."""

    task: RunTask
    attempt: int = 0
    losses: int = 0


class _Pool:
    """One campaign's runs on a process pool that is built again when a worker dies."""

    def __init__(self, workers: int, retries: int, tally: Tally) -> None:
        self.workers, self.retries, self.tally = workers, retries, tally
        self.ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
        self.pool = self._new_pool()
        self.procs: dict[int, BaseProcess] = {}
        self.flight: dict[Future[dict[str, Any]], _Run] = {}

    def _new_pool(self) -> ProcessPoolExecutor:
        return ProcessPoolExecutor(
            self.workers, mp_context=self.ctx, initializer=_worker_init, initargs=(os.getpid(),)
        )

    def run(self, tasks: Sequence[RunTask], on_result: OnResult) -> None:
        """Every task to ``on_result``; the pool shut down whatever happens."""
        queue = deque(_Run(t) for t in tasks)
        try:
            while queue or self.flight:
                if not self._fill(queue):  # broken before every worker had a run
                    queue.extendleft(reversed(self._rebuild(on_result)))
                    continue
                done, _ = wait(self.flight, return_when=FIRST_COMPLETED)
                if any(isinstance(f.exception(), BrokenProcessPool) for f in done):
                    queue.extendleft(reversed(self._rebuild(on_result)))
                    continue
                for fut in done:
                    run = self.flight.pop(fut)
                    exc = fut.exception()
                    if exc is None:
                        on_result(fut.result())
                    else:
                        queue.appendleft(self._failed(run, exc))
        except BaseException:
            self._kill()
            raise
        finally:
            self.pool.shutdown(wait=True, cancel_futures=True)

    def _fill(self, queue: deque[_Run]) -> bool:
        """Submit queued runs until every worker has one and note the workers' processes;
        False when the pool is broken (a run not yet given waits in ``queue``)."""
        known = {p.pid for p in mp.active_children()}
        ok = True
        while queue and len(self.flight) < self.workers:
            try:
                fut = self.pool.submit(execute, queue[0].task)
            except BrokenProcessPool:
                ok = False
                break
            self.flight[fut] = queue.popleft()
        for p in mp.active_children():  # a forked pool starts its processes on the first submit
            if p.pid is not None and p.pid not in known and p.pid not in self.procs:
                self.procs[p.pid] = p
        return ok

    def _rebuild(self, on_result: OnResult) -> list[_Run]:
        """The pool broke: collect what finished, count the lost worker, build a new pool; the
        runs to submit again (in their order)."""
        self.pool.shutdown(wait=True)  # every future is settled once its manager thread ends
        flight, self.flight = self.flight, {}
        lost = [run for fut, run in flight.items() if isinstance(fut.exception(), BrokenProcessPool)]
        self.tally.lost(self._dead(), [r.task.index for r in lost])
        self.pool = self._new_pool()
        again: list[_Run] = []
        for fut, run in flight.items():
            exc = fut.exception()
            if exc is None:
                on_result(fut.result())
                continue
            if isinstance(exc, BrokenProcessPool):
                run.losses += 1
                if run.losses < LOSSES_PER_ATTEMPT:
                    again.append(run)
                    continue
            again.append(self._failed(run, exc))
        return again

    def _dead(self) -> str:
        """The worker that died, for the tally: ``local process 1234 (SIGKILL)``; the pool ended
        the others with SIGTERM."""
        gone = [p for p in self.procs.values() if p.exitcode is not None and p.exitcode != -signal.SIGTERM]
        self.procs = {pid: p for pid, p in self.procs.items() if p.exitcode is None}
        if not gone:
            return "a local process"
        return ", ".join(f"local process {p.pid} ({_how(p.exitcode)})" for p in gone)

    def _failed(self, run: _Run, exc: BaseException) -> _Run:
        """``run`` failed an attempt (``exc``): the next attempt, or raise when none is left."""
        if run.attempt >= self.retries:
            if isinstance(exc, BrokenProcessPool):
                raise WorkerLostError(
                    f"run {run.task.index} lost {LOSSES_PER_ATTEMPT} local worker processes in each of "
                    f"its {run.attempt + 1} attempt(s) (killed from outside: the OOM killer, kill -9?)"
                )
            raise exc
        self.tally.retry(run.task.index)
        return _Run(run.task, run.attempt + 1)

    def _kill(self) -> None:
        """End the workers now (Ctrl-C, an error): their runs are not waited for."""
        for p in self.procs.values():
            if p.exitcode is None:
                p.kill()


def _how(exitcode: int | None) -> str:
    """``SIGKILL`` for a process killed by a signal, ``exit 1`` otherwise."""
    if exitcode is not None and exitcode < 0:
        try:
            return signal.Signals(-exitcode).name
        except ValueError:
            return f"signal {-exitcode}"
    return f"exit {exitcode}"
