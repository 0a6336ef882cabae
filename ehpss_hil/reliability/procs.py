"""Real OS processes for the reliability trials: controller, emulator and a bus logger.

Everything runs on the embedded ``udp_multicast`` bus inside a private network namespace
(:class:`~ehpss_hil.bus.netns.PrivateNetns`; hop limit 0 as in the shipped configs), so no frame can
leave the host or reach another trial. Each child's stdout+stderr go to ``<name>.out`` in the
trial directory; readiness is read from there. :class:`Trial` ends every child it started (by
its own Popen handle) when it closes.
"""

from __future__ import annotations

import json
import os
import signal
import subprocess
import sys
import time
from dataclasses import dataclass
from pathlib import Path
from types import TracebackType
from typing import Any

from .. import PROJECT_ROOT
from ..bus.netns import PrivateNetns, netns_unavailable_reason
from ..orchestrate import write_config
from ..schema import load_yaml

PY = sys.executable
CONTROLLER_YAML = PROJECT_ROOT / "configs" / "controller.yaml"
EMULATOR_YAML = PROJECT_ROOT / "configs" / "emulator.yaml"
#: what each process prints once it is on the bus (and, for the controller, has sensor data)
READY = {
    "logger": "logging ",
    "emulator": "realtime on",
    "controller": "first sensor data: ACTIVE",
    "controller-lockstep": "(lockstep)",
}


def read_json_object(path: Path) -> dict[str, Any]:
    """A JSON object written by a process of a trial (a summary, a sidecar); {} when it is
    missing, unreadable or not an object."""
    try:
        data = json.loads(path.read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}


def skip_reason() -> str | None:
    """None when cross-process trials can run here, else why not."""
    why = netns_unavailable_reason()
    return None if why is None else f"cross-process trials need a private network namespace: {why}"


@dataclass
class Child:
    """One child process; output in ``out_path``."""

    name: str
    popen: subprocess.Popen[bytes]
    out_path: Path

    @property
    def pid(self) -> int:
        """Process id (nsenter execs the command: the same PID)."""
        return self.popen.pid

    def text(self) -> str:
        """Everything it printed so far."""
        try:
            return self.out_path.read_text(errors="replace")
        except OSError:
            return ""

    def wait_text(self, needle: str, timeout_s: float = 60.0) -> bool:
        """Wait until ``needle`` appears in its output (False: it ended or the limit passed)."""
        end = time.monotonic() + timeout_s
        while time.monotonic() < end:
            if needle in self.text():
                return True
            if self.popen.poll() is not None:
                return needle in self.text()
            time.sleep(0.02)
        return False

    def wait(self, timeout_s: float = 60.0) -> int | None:
        """Exit code, or None when it did not end within ``timeout_s`` (s)."""
        try:
            return self.popen.wait(timeout=timeout_s)
        except subprocess.TimeoutExpired:
            return None

    def terminate(self, timeout_s: float = 30.0) -> int | None:
        """SIGTERM and wait; SIGKILL if it does not end in ``timeout_s``. Returns the exit code
        (None when it had to be killed)."""
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGTERM)
        rc = self.wait(timeout_s)
        if rc is None:
            self.kill9()
        return rc

    def kill9(self) -> None:
        """SIGKILL (no handler runs, nothing is flushed) and reap it."""
        if self.popen.poll() is None:
            self.popen.send_signal(signal.SIGKILL)
        self.popen.wait()


class Trial:
    """A trial directory and a private network namespace holding its processes (``netns``
    False: this process's namespace, for a bus that lives there, SocketCAN's vcan0)."""

    def __init__(self, out_dir: Path, netns: bool = True) -> None:
        self.dir = out_dir
        self.dir.mkdir(parents=True, exist_ok=True)
        self.children: dict[str, Child] = {}
        self.netns = netns
        self._ns: PrivateNetns | None = None
        self._open = False

    def __enter__(self) -> Trial:
        if self.netns:
            self._ns = PrivateNetns().start()
        self._open = True
        return self

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> None:
        self.close()

    def close(self) -> None:
        """Kill whatever is still running, then drop the namespace."""
        for c in self.children.values():
            c.kill9()
        if self._ns is not None:
            self._ns.close()
            self._ns = None
        self._open = False

    def spawn(self, name: str, argv: list[str]) -> Child:
        """Start ``argv`` inside the namespace (cwd: the project root)."""
        assert self._open, "use Trial as a context manager"
        prefix = self._ns.prefix() if self._ns is not None else []
        out = self.dir / f"{name}.out"
        env = {**os.environ, "PYTHONUNBUFFERED": "1"}
        with open(out, "wb") as f:
            p = subprocess.Popen(
                [*prefix, *argv],
                stdout=f,
                stderr=subprocess.STDOUT,
                stdin=subprocess.DEVNULL,
                cwd=PROJECT_ROOT,
                env=env,
            )
        child = Child(name, p, out)
        self.children[name] = child
        return child

    # ---- the project's processes ------------------------------------------------------------
    def logger(self, name: str = "logger") -> Child:
        """``ehpss-hil log`` on the configs' bus, writing ``<name>.log``; waits until it listens."""
        bus = (load_yaml(CONTROLLER_YAML) or {}).get("bus", {})
        c = self.spawn(
            name,
            [
                PY,
                "-m",
                "ehpss_hil.cli",
                "log",
                "-i",
                bus["interface"],
                "-c",
                str(bus["channel"]),
                "-o",
                str(self.dir / f"{name}.log"),
            ],
        )
        if not c.wait_text(READY["logger"]):
            raise RuntimeError(f"bus logger did not start: {c.text()[-500:]}")
        return c

    def _outputs(self, name: str, log: bool) -> list[str]:
        out = ["--summary-json", str(self.dir / f"{name}.json")]
        return [*out, "--log", str(self.dir / f"{name}.log")] if log else out

    def controller(
        self,
        overrides: dict[str, Any],
        *args: str,
        name: str = "controller",
        log: bool = True,
        base: Path = CONTROLLER_YAML,
    ) -> Child:
        """``ehpss-hil controller`` with ``base`` (``configs/controller.yaml``) + ``overrides``,
        its summary ``<name>.json`` and (``log``) its candump log ``<name>.log``."""
        cfg = write_config(base, self.dir / f"{name}.yaml", overrides)
        return self.spawn(
            name, [PY, "-m", "ehpss_hil.cli", "controller", "-c", str(cfg), *self._outputs(name, log), *args]
        )

    def emulator(
        self,
        overrides: dict[str, Any],
        *args: str,
        name: str = "emulator",
        log: bool = True,
        base: Path = EMULATOR_YAML,
    ) -> Child:
        """``firmware-sim`` with ``base`` (``configs/emulator.yaml``) + ``overrides``, summary
        and log."""
        cfg = write_config(base, self.dir / f"{name}.yaml", overrides)
        return self.spawn(
            name, [PY, "-m", "firmware_sim.cli", "-c", str(cfg), *self._outputs(name, log), *args]
        )
