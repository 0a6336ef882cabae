"""Where campaign runs execute: local processes, or a Dask cluster (``dask.distributed``).

Both take the runs to do and a callback called in the main process with each finished record, in
completion order (the table is sorted by run index afterwards, so the order does not matter).
Ctrl-C (KeyboardInterrupt) stops the workers and propagates; what the callback got is kept.
"""

from __future__ import annotations

import multiprocessing as mp
import os
import signal
from collections.abc import Callable, Sequence
from typing import Any

from ..blas import limit_blas_threads
from ..errors import ClusterError
from .runs import RunTask, execute

OnResult = Callable[[dict[str, Any]], None]
#: how long to wait for the Dask scheduler to answer (s)
CONNECT_TIMEOUT_S = 30.0


def default_workers() -> int:
    """Local worker processes by default: every core."""
    return os.cpu_count() or 1


def _worker_init() -> None:
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the main process handles Ctrl-C
    limit_blas_threads(1)


def run_local(tasks: Sequence[RunTask], workers: int, on_result: OnResult) -> None:
    """Run ``tasks`` on ``workers`` processes (1: in this process)."""
    limit_blas_threads(1)  # before forking: no spinning BLAS pool to inherit
    if workers <= 1 or len(tasks) <= 1:
        for t in tasks:
            on_result(execute(t))
        return
    ctx = mp.get_context("fork" if "fork" in mp.get_all_start_methods() else "spawn")
    pool = ctx.Pool(min(workers, len(tasks)), initializer=_worker_init)
    try:
        for rec in pool.imap_unordered(execute, tasks, chunksize=1):
            on_result(rec)
        pool.close()
    except BaseException:
        pool.terminate()
        raise
    finally:
        pool.join()


def run_dask(tasks: Sequence[RunTask], address: str, on_result: OnResult) -> None:
    """Run ``tasks`` on the Dask cluster whose scheduler listens at ``address``
    (``tcp://host:8786``); ClusterError when it cannot be reached."""
    from distributed import Client, as_completed
    from distributed.comm import parse_address
    from distributed.comm.registry import get_backend

    try:  # a bad address before a Client exists (a half-built one hangs in its finalizer)
        get_backend(parse_address(address)[0])
    except (ValueError, TypeError) as exc:
        raise ClusterError(f"bad Dask scheduler address {address!r}: {exc}") from exc
    try:
        client = Client(address, timeout=CONNECT_TIMEOUT_S, set_as_default=False)
    except (OSError, TimeoutError, ValueError) as exc:
        raise ClusterError(f"cannot reach the Dask scheduler at {address}: {exc}") from exc
    futures = []
    try:
        futures = client.map(execute, list(tasks), key=[f"campaign-run-{t.run_hash}" for t in tasks])
        for fut in as_completed(futures, loop=client.loop):
            on_result(fut.result())
    finally:
        client.cancel(futures)
        client.close()
