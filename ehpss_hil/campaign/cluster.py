"""Campaign runs on Dask (``dask.distributed``): a scheduler given by its address, or a
``distributed.LocalCluster`` on this machine (``--scheduler local[:N]``).

:class:`DaskExecutor` connects (or starts the local cluster) before the campaign touches its
output directory, so an unreachable scheduler leaves nothing behind. While the runs execute it
listens to the scheduler's ``all`` event topic: a worker removed without being retired is a
**lost worker**, and the runs it was processing, which Dask starts again elsewhere, are
**retried**. A run that raises (or that Dask gives up on after its own allowed failures,
``KilledWorker``) is submitted again up to ``retries`` times and counted as retried too.
"""

from __future__ import annotations

import importlib.util
import logging
import os
import signal
import threading
import warnings
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from types import TracebackType
from typing import Any

from distributed import WorkerPlugin

from ..errors import ClusterError, ConfigError, EhpssError
from .runs import RunTask, execute
from .workers import CONNECT_TIMEOUT_S, OnResult, Tally, default_workers

#: ``--scheduler`` value that starts a LocalCluster here (``local`` or ``local:N``)
LOCAL = "local"
#: most worker processes of a LocalCluster per core (one thread each: more only share the cores)
MAX_LOCAL_PER_CORE = 4
#: where the local cluster serves its dashboard (Dask's default; another free port when taken)
DASHBOARD_ADDRESS = ":8787"
#: the scheduler's event topic that carries ``remove-worker``
EVENT_TOPIC = "all"
#: a run's task key: the run hash, so a key names the same run on every cluster
KEY_PREFIX = "campaign-run-"
#: how a Dask worker logs a heartbeat that found the scheduler gone (``Worker.heartbeat``;
#: tests/test_campaign_dask.py fails when distributed words it otherwise)
HEARTBEAT_LOST = "Failed to communicate with scheduler during heartbeat"
#: where distributed's ``sync`` lives (the tail of its file name; :class:`SyncCancelFilter`)
SYNC_MODULE_TAIL = os.path.join("distributed", "utils.py")


class SchedulerGoneFilter(logging.Filter):
    """Drops a local worker's "Failed to communicate with scheduler during heartbeat" record
    (with its traceback). A LocalCluster's scheduler lives in the campaign's own process: a
    worker loses it only while the campaign closes the cluster (a Ctrl-C: one heartbeat in
    flight as the scheduler went printed a traceback about one time in ten), and a campaign
    whose scheduler failed says so itself."""

    def filter(self, record: logging.LogRecord) -> bool:
        """False for the heartbeat record, True for every other."""
        return not (isinstance(record.msg, str) and record.msg.startswith(HEARTBEAT_LOST))


class SyncCancelFilter(logging.Filter):
    """Drops tornado's record of distributed's ``sync`` cancel callback failing with a
    NameError. A Ctrl-C that lands in ``distributed.utils.sync`` before its coroutine has bound
    ``future`` schedules ``cancel``, which reads the unbound name (distributed 2026.8.0): tornado
    logs that with a traceback, about one Ctrl-C in thirty here, while the campaign stops on the
    interrupt all the same. tests/test_campaign_dask.py fails when ``sync`` changes."""

    def filter(self, record: logging.LogRecord) -> bool:
        """False for that record, True for every other."""
        exc = record.exc_info[1] if record.exc_info else None
        if not isinstance(exc, NameError):
            return True
        tb = exc.__traceback__
        while tb is not None and tb.tb_next is not None:
            tb = tb.tb_next
        if tb is None:
            return True
        code = tb.tb_frame.f_code
        return not (code.co_name == "cancel" and code.co_filename.endswith(SYNC_MODULE_TAIL))


def _filter_once(logger: str, kind: type[logging.Filter]) -> None:
    """Give the logger named ``logger`` a ``kind`` filter unless it has one (a plugin set up
    again, a second executor in one process)."""
    log = logging.getLogger(logger)
    if not any(isinstance(f, kind) for f in log.filters):
        log.addFilter(kind())


class IgnoreInterrupt(WorkerPlugin):
    """Makes a LocalCluster's worker ignore SIGINT: a Ctrl-C in the terminal reaches the whole
    process group, and the campaign, not each worker (with a KeyboardInterrupt traceback), stops
    the cluster. The workers started with the cluster inherit it (:func:`_interrupts_ignored`);
    registered with the client, this plugin gives it to a worker the nanny restarts. It also
    keeps the worker's heartbeat quiet when the closing cluster's scheduler goes first
    (:class:`SchedulerGoneFilter`)."""

    name = "ehpss-ignore-interrupt"

    def setup(self, worker: Any) -> None:
        """Ignore SIGINT in this worker process (its event loop runs in the main thread), and
        filter its scheduler-gone heartbeat record."""
        if threading.current_thread() is threading.main_thread():
            signal.signal(signal.SIGINT, signal.SIG_IGN)
        _filter_once("distributed.worker", SchedulerGoneFilter)


@contextmanager
def _interrupts_ignored() -> Iterator[None]:
    """SIGINT ignored while the LocalCluster starts: its worker processes inherit that (a Ctrl-C
    then stops the campaign, which closes them, instead of each printing a KeyboardInterrupt
    traceback), and a cluster half started is not torn down from an atexit hook. A Ctrl-C in
    those seconds is lost; the next one stops the campaign."""
    if threading.current_thread() is not threading.main_thread():
        yield
        return
    before = signal.signal(signal.SIGINT, signal.SIG_IGN)
    try:
        yield
    finally:
        signal.signal(signal.SIGINT, before)


def parse_local(scheduler: str) -> int | None:
    """Workers of a ``local[:N]`` scheduler (``local``: every core); None for an address.
    ConfigError (exit 2) for ``local:`` with anything but a whole number from 1 to
    :data:`MAX_LOCAL_PER_CORE` × the cores."""
    if scheduler != LOCAL and not scheduler.startswith(LOCAL + ":"):
        return None
    text = scheduler[len(LOCAL) + 1 :]
    if not text:
        return default_workers()
    most = MAX_LOCAL_PER_CORE * default_workers()
    if not text.isdigit() or not 1 <= int(text) <= most:
        raise ConfigError(
            "",
            "--scheduler",
            f"expected local, local:N with 1 ≤ N ≤ {most}, or tcp://host:port, got {scheduler!r}",
        )
    return int(text)


def _check_address(address: str) -> None:
    """A bad address fails here, before a Client exists (a half-built one hangs in its finalizer)."""
    from distributed.comm import parse_address
    from distributed.comm.registry import get_backend

    try:
        get_backend(parse_address(address)[0])
    except (ValueError, TypeError) as exc:
        raise ClusterError(f"bad Dask scheduler address {address!r}: {exc}") from exc


class DaskExecutor:
    """``with DaskExecutor("local:2") as ex: ex.run(tasks, on_result, tally)``; ``ex.client`` is
    the ``distributed.Client``, ``ex.dashboard`` the link Dask gives for its dashboard."""

    def __init__(
        self, scheduler: str, retries: int = 0, connect_timeout_s: float = CONNECT_TIMEOUT_S
    ) -> None:
        """``connect_timeout_s``: how long a scheduler address may take to answer (s; a closed
        port is retried until then)."""
        self.scheduler, self.retries = scheduler, retries
        self.connect_timeout_s = connect_timeout_s
        self.local_workers = parse_local(scheduler)
        self.cluster: Any = None
        self.client: Any = None
        self.description = f"Dask scheduler {scheduler}"
        self.dashboard = ""

    def __enter__(self) -> DaskExecutor:
        _filter_once("tornado.application", SyncCancelFilter)
        try:
            self._connect()
        except BaseException:
            self.close()
            raise
        return self

    def _connect(self) -> None:
        from distributed import Client, LocalCluster

        if self.local_workers is None:
            _check_address(self.scheduler)
            target: Any = self.scheduler
        else:
            try:
                with warnings.catch_warnings(), _interrupts_ignored():
                    warnings.simplefilter("ignore", UserWarning)  # "Port 8787 is already in use"
                    self.cluster = LocalCluster(
                        n_workers=self.local_workers,
                        threads_per_worker=1,
                        processes=True,
                        host="127.0.0.1",
                        dashboard_address=DASHBOARD_ADDRESS,
                        silence_logs=logging.ERROR,
                    )
            except (OSError, TimeoutError, RuntimeError) as exc:
                raise ClusterError(f"cannot start a Dask LocalCluster: {exc}") from exc
            target = self.cluster
            n = self.local_workers
            self.description = (
                f"Dask LocalCluster ({n} worker process{'es' if n > 1 else ''} × 1 thread, "
                f"scheduler {self.cluster.scheduler_address})"
            )
        try:
            self.client = Client(target, timeout=self.connect_timeout_s, set_as_default=False)
        except (OSError, TimeoutError, ValueError) as exc:
            raise ClusterError(f"cannot reach the Dask scheduler at {self.scheduler}: {exc}") from exc
        if self.cluster is not None:
            self.client.register_plugin(IgnoreInterrupt())
        self.dashboard = self.client.dashboard_link or ""
        if self.dashboard and self.cluster is not None and importlib.util.find_spec("bokeh") is None:
            self.dashboard += " (bokeh is not installed: the page says what to install for the dashboard)"

    def run(self, tasks: Sequence[RunTask], on_result: OnResult, tally: Tally) -> None:
        """Run ``tasks``; ``on_result`` gets each record in completion order, ``tally`` the lost
        workers and retried runs. A run that still fails after its retries raises (its own
        EhpssError, else ClusterError naming the run); the other runs are cancelled."""
        from distributed import as_completed

        client = self.client
        pending: dict[str, tuple[RunTask, int]] = {KEY_PREFIX + t.run_hash: (t, 0) for t in tasks}

        def on_event(event: tuple[float, Any]) -> None:
            msg = event[1]
            if isinstance(msg, dict) and msg.get("action") == "remove-worker" and not msg.get("expected"):
                keys = msg.get("processing-tasks") or ()
                runs = [p[0].index for k in keys if (p := pending.get(k)) is not None]
                tally.lost(str(msg.get("worker")), runs)

        client.subscribe_topic(EVENT_TOPIC, on_event)
        # a finished run's future is dropped once used: a lost worker would make Dask recompute it
        futures = {f.key: f for f in client.map(execute, list(tasks), key=list(pending), pure=False)}
        ac = as_completed(futures.values(), loop=client.loop)
        try:
            for fut in ac:
                task, attempt = pending[fut.key]
                if fut.status != "finished" and attempt >= self.retries:
                    raise self._failure(fut, task, attempt)
                rec = fut.result() if fut.status == "finished" else None
                del pending[fut.key], futures[fut.key]
                fut.release()
                if rec is not None:
                    on_result(rec)
                    continue
                key = f"{KEY_PREFIX}{task.run_hash}-retry{attempt + 1}"
                pending[key] = (task, attempt + 1)
                futures[key] = client.submit(execute, task, key=key, pure=False)
                tally.retry(task.index)
                ac.add(futures[key])
        finally:
            ac.clear()
            client.cancel(list(futures.values()))
            client.unsubscribe_topic(EVENT_TOPIC)

    @staticmethod
    def _failure(fut: Any, task: RunTask, attempt: int) -> BaseException:
        """The error of a run that failed its last attempt."""
        try:
            exc = fut.exception()
        except BaseException as why:  # cancelled: there is no exception to fetch
            exc = why
        if isinstance(exc, EhpssError):
            return exc
        what = f"{type(exc).__name__}: {exc}" if exc is not None else fut.status
        return ClusterError(f"run {task.index} failed after {attempt + 1} attempt(s) on Dask: {what}")

    def close(self) -> None:
        """Close the client, then the local cluster (its workers and scheduler)."""
        if self.client is not None:
            self.client.close()
            self.client = None
        if self.cluster is not None:
            self.cluster.close()
            self.cluster = None

    def __exit__(
        self, tp: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
