"""A Dask cluster on this machine, as separate processes: ``dask scheduler`` and N ``dask worker``
on 127.0.0.1 only (no dashboard), one thread each. Used by the tests and ``bench campaign``; a
real cluster is started the same way on its machines (docs/campaigns.md).
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
import tempfile
import time
from pathlib import Path
from types import TracebackType

from ..errors import ClusterError

#: how long the scheduler and workers may take to come up (s; a loaded host is slow)
START_TIMEOUT_S = 120.0
#: how long a process may take to stop after SIGTERM before it is killed (s)
STOP_TIMEOUT_S = 10.0


def _dask() -> str:
    exe = Path(sys.executable).with_name("dask")
    found = str(exe) if exe.exists() else shutil.which("dask")
    if not found:
        raise ClusterError("the dask command is not installed (pip install 'dask[distributed]')")
    return found


class LocalDaskCluster:
    """``with LocalDaskCluster(2) as c: c.address`` → ``tcp://127.0.0.1:PORT``."""

    def __init__(self, workers: int = 2) -> None:
        self.workers = workers
        self.address = ""
        self._procs: list[subprocess.Popen[bytes]] = []
        self._tmp = tempfile.TemporaryDirectory(prefix="ehpss-dask-")

    def __enter__(self) -> LocalDaskCluster:
        try:
            self._start()
        except BaseException:
            self.close()
            raise
        return self

    def _spawn(self, args: list[str], log: str) -> None:
        env = {**os.environ, "OPENBLAS_NUM_THREADS": "1", "OMP_NUM_THREADS": "1", "MKL_NUM_THREADS": "1"}
        with open(Path(self._tmp.name) / log, "wb") as out:
            self._procs.append(
                subprocess.Popen(
                    [_dask(), *args], stdout=out, stderr=subprocess.STDOUT, env=env, cwd=self._tmp.name
                )
            )

    def _start(self) -> None:
        sched_file = Path(self._tmp.name) / "scheduler.json"
        self._spawn(
            [
                "scheduler",
                "--host",
                "127.0.0.1",
                "--port",
                "0",
                "--no-dashboard",
                "--scheduler-file",
                str(sched_file),
            ],
            "scheduler.log",
        )
        deadline = time.monotonic() + START_TIMEOUT_S
        while not sched_file.exists() or not sched_file.read_text().strip():
            if time.monotonic() > deadline or self._procs[0].poll() is not None:
                raise ClusterError(f"the dask scheduler did not start: {self.log('scheduler.log')}")
            time.sleep(0.05)
        self.address = json.loads(sched_file.read_text())["address"]
        for i in range(self.workers):
            self._spawn(
                [
                    "worker",
                    self.address,
                    "--host",
                    "127.0.0.1",
                    "--nthreads",
                    "1",
                    "--no-nanny",
                    "--no-dashboard",
                    "--name",
                    f"w{i}",
                    "--local-directory",
                    self._tmp.name,
                ],
                f"worker{i}.log",
            )
        from distributed import Client

        with Client(self.address, timeout=START_TIMEOUT_S, set_as_default=False) as client:
            client.wait_for_workers(self.workers, timeout=START_TIMEOUT_S)

    def log(self, name: str) -> str:
        """The last lines of one of the cluster's logs (for an error message)."""
        path = Path(self._tmp.name) / name
        return " | ".join(path.read_text(errors="replace").splitlines()[-5:]) if path.exists() else ""

    def close(self) -> None:
        """Stop the workers, then the scheduler (SIGTERM, then SIGKILL after a grace)."""
        for p in reversed(self._procs):
            if p.poll() is None:
                p.terminate()
        for p in reversed(self._procs):
            try:
                p.wait(STOP_TIMEOUT_S)
            except subprocess.TimeoutExpired:
                p.kill()
                p.wait()
        self._procs.clear()
        self._tmp.cleanup()

    def __exit__(
        self, tp: type[BaseException] | None, exc: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()
