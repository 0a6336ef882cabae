"""Where campaign runs execute: local processes (:class:`~.localpool.LocalPool`), or Dask
(:class:`~ehpss_hil.campaign.cluster.DaskExecutor`: a scheduler's address or a LocalCluster).

Every executor takes the runs to do, a callback called in the main process with each finished
record, in completion order (the table is sorted by run index afterwards, so the order does not
matter), and a :class:`~.workers.Tally` of the workers lost and the runs retried. Ctrl-C
(KeyboardInterrupt) stops the workers and propagates; what the callback got is kept.
"""

from __future__ import annotations

from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from typing import Protocol

from .localpool import LocalPool
from .runs import RunTask
from .workers import CONNECT_TIMEOUT_S, OnResult, Tally


class Executor(Protocol):
    """Runs campaign tasks somewhere; ``description`` says where, ``dashboard`` is a link to
    watch it (empty: none)."""

    @property
    def description(self) -> str:
        """Where the runs go (one line)."""

    dashboard: str

    def run(self, tasks: Sequence[RunTask], on_result: OnResult, tally: Tally) -> None:
        """Run every task, ``on_result`` with each record."""


@contextmanager
def open_executor(
    workers: int = 1,
    scheduler: str | None = None,
    retries: int = 0,
    connect_timeout_s: float = CONNECT_TIMEOUT_S,
) -> Iterator[Executor]:
    """The executor of ``--workers``/``--scheduler`` (Dask connected, or its LocalCluster up,
    on entry: ClusterError when it cannot be); closed on exit. A run that fails is submitted
    again up to ``retries`` times; ``connect_timeout_s``: how long the scheduler may take to
    answer (s)."""
    if not scheduler:
        yield LocalPool(workers, retries)
        return
    from .cluster import DaskExecutor

    with DaskExecutor(scheduler, retries, connect_timeout_s) as ex:
        yield ex
