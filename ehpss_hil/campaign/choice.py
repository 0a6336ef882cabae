"""The executor a campaign runs on: the local pool of ``--workers`` or Dask (``--scheduler``)."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import contextmanager

from .executors import Executor, LocalPool


@contextmanager
def open_executor(workers: int = 1, scheduler: str | None = None, retries: int = 0) -> Iterator[Executor]:
    """The executor of ``--workers``/``--scheduler`` (Dask connected, or its LocalCluster up,
    on entry: ClusterError when it cannot be); closed on exit."""
    if not scheduler:
        yield LocalPool(workers)
        return
    from .cluster import DaskExecutor  # distributed only when a scheduler is asked for

    with DaskExecutor(scheduler, retries) as ex:
        yield ex
