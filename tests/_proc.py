"""Helpers for tests that start real OS processes (no timing asserts: waits have generous
limits only so that a broken run fails instead of hanging)."""

from __future__ import annotations

import os
import queue
import subprocess
import sys
import threading
import time
from pathlib import Path
from typing import Any

from ehpss_hil.orchestrate import RunPlan

ROOT = Path(__file__).resolve().parent.parent
PY = sys.executable
FIRMWARE_SIM = [PY, "-m", "firmware_sim.cli"]
EHPSS_HIL = [PY, "-m", "ehpss_hil.cli"]
EMU_CFG_PATH = str(ROOT / "configs" / "emulator.yaml")
CLIENT = [PY, str(ROOT / "tests" / "udp_client.py")]
ENV = {**os.environ, "PYTHONUNBUFFERED": "1"}
#: how long ``ehpss-hil run`` may wait for each process to come up in a test (s): a hang guard
#: only — in the vcan VM (Python ~10x slower) on a loaded host the controller took over 60 s
STARTUP_LIMIT_S = 600.0


def lockstep_plan(scenario: Path, out: Path, mode: str, **extra: Any) -> RunPlan:
    """``ehpss-hil run --lockstep`` of ``scenario`` into ``out`` with the tests' hang guards
    (``STARTUP_LIMIT_S`` to come up and to finish: a loaded VM takes its time); ``extra``:
    more :class:`RunPlan` fields (the bus, …)."""
    return RunPlan(
        scenario_path=scenario,
        mode=mode,
        out_dir=out,
        lockstep=True,
        finish_timeout_s=STARTUP_LIMIT_S,
        startup_timeout_s=STARTUP_LIMIT_S,
        **extra,
    )


class Proc:
    """A child process whose stdout/stderr lines are collected by reader threads."""

    def __init__(self, argv: list[str]) -> None:
        self.argv = argv
        self.p = subprocess.Popen(
            argv, cwd=ROOT, env=ENV, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True
        )
        self.out: list[str] = []
        self.err: list[str] = []
        self._q: queue.Queue[tuple[str, str]] = queue.Queue()
        self._threads = [
            threading.Thread(target=self._read, args=(stream, sink, tag), daemon=True)
            for stream, sink, tag in ((self.p.stdout, self.out, "out"), (self.p.stderr, self.err, "err"))
        ]
        for t in self._threads:
            t.start()

    def _read(self, stream: object, sink: list[str], tag: str) -> None:
        for line in stream:  # type: ignore[attr-defined]
            sink.append(line)
            self._q.put((tag, line))
        self._q.put((tag, ""))

    def wait_for(self, text: str, limit_s: float = 30.0) -> bool:
        """Block until a line containing ``text`` appears (False on EOF, or once ``limit_s`` has
        passed in all: a child that keeps printing other lines does not hold the wait open)."""
        for line in self.out + self.err:
            if text in line:
                return True
        eof = 0
        deadline = time.monotonic() + limit_s
        while (left := deadline - time.monotonic()) > 0.0:
            try:
                _, line = self._q.get(timeout=left)
            except queue.Empty:
                return False
            if line == "":
                eof += 1
                if eof == 2:
                    return False
            elif text in line:
                return True
        return False

    def wait(self, limit_s: float = 60.0) -> int:
        """Exit code (kills the child if it does not end within ``limit_s``)."""
        try:
            rc = self.p.wait(timeout=limit_s)
            for t in self._threads:
                t.join(timeout=10.0)
            return rc
        except subprocess.TimeoutExpired as exc:
            self.p.kill()
            self.p.wait()
            raise AssertionError(f"{self.argv} did not end; stderr: {''.join(self.err)[-2000:]}") from exc

    def terminate(self) -> None:
        if self.p.poll() is None:
            self.p.terminate()

    def kill(self) -> None:
        if self.p.poll() is None:
            self.p.kill()
            self.p.wait()

    @property
    def text(self) -> str:
        return "".join(self.out) + "".join(self.err)
