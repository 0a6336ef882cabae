"""Hostile surroundings of a run (issue #16): foreign files in ``--out`` and a full disk.

- :func:`foreign_files_trial`: ``ehpss-hil run --out`` on a folder holding files no run wrote
  (``app.log.1``, ``syslog.log``, ``catalog.logbook``, ``notes.out``): refused with exit 2 and one
  line; with ``--overwrite`` the run goes ahead and all four are still there.
- :func:`disk_full_trial`: the controller and the emulator with ``--log`` (and their exit
  summaries) on a 200 kB tmpfs, a run long enough to fill it, then SIGTERM: both exit 0, the
  summaries are written, every sidecar is closed and counts exactly the lines in its log
  (whole lines only), no ``.tmp`` is left, and ``ehpss-hil replay`` reads the log.

Both need root (namespaces, ``mount``); :func:`tmpfs_unavailable_reason` says why not.
"""

from __future__ import annotations

import json
import os
import subprocess
import time
from dataclasses import dataclass, field
from pathlib import Path
from types import TracebackType
from typing import Any

from .. import PROJECT_ROOT
from ..runtime.rtverdict import REALTIME_INVALID_EXIT
from .procs import PY, Trial

FOREIGN = ("app.log.1", "syslog.log", "catalog.logbook", "notes.out")
TMPFS_SIZE = "200k"


def tmpfs_unavailable_reason() -> str | None:
    """None when a small tmpfs can be mounted here (root + mount), else why not."""
    if os.geteuid() != 0:
        return "mounting a small tmpfs needs root"
    return None


class SmallTmpfs:
    """A tmpfs of ``size`` mounted on ``where`` (made if needed) for the ``with`` block."""

    def __init__(self, where: Path, size: str = TMPFS_SIZE) -> None:
        self.where = where
        self.size = size

    def __enter__(self) -> Path:
        self.where.mkdir(parents=True, exist_ok=True)
        subprocess.run(
            ["mount", "-t", "tmpfs", "-o", f"size={self.size}", "tmpfs", str(self.where)],
            check=True,
            capture_output=True,
        )
        return self.where

    def __exit__(
        self, et: type[BaseException] | None, ev: BaseException | None, tb: TracebackType | None
    ) -> None:
        """Unmount; a file system still busy (a file left open on it) is detached lazily and,
        unless the block already failed, raised as an error: no mount outlives the block."""
        done = subprocess.run(["umount", str(self.where)], check=False, capture_output=True)
        if done.returncode != 0:
            subprocess.run(["umount", "-l", str(self.where)], check=False, capture_output=True)
            if et is None:
                msg = done.stderr.decode(errors="replace").strip()
                raise RuntimeError(f"{self.where}: {msg or 'umount failed'} (a file left open on it?)")


def short_scenario(path: Path, duration_s: float = 0.5) -> Path:
    """Write a short scenario (the paper's sine, a loss of effectiveness at 0.3 s) to ``path``."""
    path.write_text(f"""\
name: short
duration_s: {duration_s}
sample_time_s: 0.001
seed: 3
reference: {{kind: sine, amplitude_m: 0.001, omega_rad_s: 5.0}}
transport_delay_samples: 1
events:
  - {{t_s: 0.3, k_loe: 0.5}}
""")
    return path


@dataclass
class ForeignResult:
    """``run --out`` on a folder of foreign files: without and with ``--overwrite``."""

    refused_exit: int | None = None
    refused_lines: list[str] = field(default_factory=list)
    kept_after_refusal: int = 0
    overwrite_exit: int | None = None
    kept_after_run: int = 0
    run_files: int = 0

    @property
    def ok(self) -> bool:
        """Refused with exit 2 and one line; every foreign file kept both times; the run ran."""
        return (
            self.refused_exit == 2
            and len(self.refused_lines) == 1
            and self.kept_after_refusal == self.kept_after_run == len(FOREIGN)
            and self.overwrite_exit in (0, REALTIME_INVALID_EXIT)  # completed; 4: host too busy
            and self.run_files > 0
        )


def _run_cli(args: list[str], timeout_s: float = 120.0) -> tuple[int | None, list[str]]:
    try:
        r = subprocess.run(
            [PY, "-m", "ehpss_hil.cli", *args],
            cwd=PROJECT_ROOT,
            capture_output=True,
            text=True,
            timeout=timeout_s,
        )
    except subprocess.TimeoutExpired:
        return None, []
    return r.returncode, [ln for ln in (r.stdout + r.stderr).splitlines() if ln.strip()]


def foreign_files_trial(out: Path, scenario: Path) -> ForeignResult:
    """``ehpss-hil run scenario --out out/foreign`` without, then with ``--overwrite``."""
    d = out / "foreign"
    d.mkdir(parents=True, exist_ok=True)
    for name in FOREIGN:
        (d / name).write_text(f"{name}: not written by ehpss-hil\n")
    res = ForeignResult()
    res.refused_exit, res.refused_lines = _run_cli(["run", str(scenario), "--out", str(d)])
    res.kept_after_refusal = sum((d / n).exists() for n in FOREIGN)
    res.overwrite_exit, _ = _run_cli(["run", str(scenario), "--out", str(d), "--overwrite"])
    res.kept_after_run = sum((d / n).exists() for n in FOREIGN)
    res.run_files = sum((d / n).exists() for n in ("run.json", "bus.log", "metrics.json"))
    return res


@dataclass
class LogState:
    """One candump log after the run: its lines and what its sidecar says."""

    lines: int = 0
    whole_lines: bool = True
    status: str = ""
    written: int = -1
    dropped: int = -1
    reasons: dict[str, int] = field(default_factory=dict)

    @property
    def ok(self) -> bool:
        """Closed, whole lines, and the sidecar counts exactly the lines in the file."""
        return self.whole_lines and self.status == "closed" and self.written == self.lines


@dataclass
class DiskFullResult:
    """Controller and emulator logging to a full tmpfs."""

    exits: dict[str, int | None] = field(default_factory=dict)
    summaries: dict[str, bool] = field(default_factory=dict)
    logs: dict[str, LogState] = field(default_factory=dict)
    warned: bool = False
    tmp_left: list[str] = field(default_factory=list)
    replay_exit: int | None = None
    error: str = ""

    @property
    def dropped(self) -> int:
        """Lines the processes could not write (the disk was full: must be > 0)."""
        return sum(max(0, s.dropped) for s in self.logs.values())

    @property
    def ok(self) -> bool:
        """Exit 0 everywhere, summaries written, exact sidecars, a warning, no .tmp, replay
        reads the controller's log, and the disk did fill up."""
        return (
            not self.error
            and all(v == 0 for v in self.exits.values())
            and all(self.summaries.values())
            and all(s.ok for s in self.logs.values())
            and self.warned
            and not self.tmp_left
            and self.replay_exit in (0, 1)
            and self.dropped > 0
        )


def _log_state(path: Path) -> LogState:
    raw = path.read_bytes() if path.exists() else b""
    st = LogState(lines=raw.count(b"\n"), whole_lines=not raw or raw.endswith(b"\n"))
    try:
        side: dict[str, Any] = json.loads(path.with_name(path.name + ".json").read_text())
    except (OSError, ValueError):
        return st
    counts = side.get("counts") or {}
    st.status = str(side.get("status"))
    st.written = int(counts.get("written", -1))
    st.dropped = int(counts.get("dropped", -1))
    st.reasons = dict(counts.get("dropped_by_reason") or {})
    return st


def disk_full_trial(out: Path, seconds: float = 4.0) -> DiskFullResult:
    """Both processes with their logs and summaries on a 200 kB tmpfs for ``seconds`` (s)."""
    res = DiskFullResult()
    with SmallTmpfs(out / "tmpfs") as full, Trial(out) as t:
        ctrl = t.spawn(
            "controller",
            [
                PY,
                "-m",
                "ehpss_hil.cli",
                "controller",
                "-c",
                str(PROJECT_ROOT / "configs" / "controller.yaml"),
                "--log",
                str(full / "controller.log"),
                "--summary-json",
                str(full / "controller.json"),
            ],
        )
        emu = t.spawn(
            "emulator",
            [
                PY,
                "-m",
                "firmware_sim.cli",
                "-c",
                str(PROJECT_ROOT / "configs" / "emulator.yaml"),
                "--log",
                str(full / "emulator.log"),
                "--summary-json",
                str(full / "emulator.json"),
                "--duration",
                repr(seconds),
            ],
        )
        res.exits["emulator"] = emu.wait(seconds + 60.0)
        time.sleep(0.1)
        res.exits["controller"] = ctrl.terminate()
        res.warned = "cannot write" in ctrl.text() + emu.text()
        for name in ("controller", "emulator"):
            res.summaries[name] = (full / f"{name}.json").exists()
            res.logs[name] = _log_state(full / f"{name}.log")
        res.tmp_left = sorted(p.name for p in full.iterdir() if p.name.endswith(".tmp"))
        r = subprocess.run(
            [PY, "-m", "ehpss_hil.cli", "replay", str(full / "controller.log")],
            cwd=PROJECT_ROOT,
            capture_output=True,
            text=True,
            timeout=120,
        )
        res.replay_exit = r.returncode  # 0 identical, 1 diverged: both read the whole log
        if r.returncode not in (0, 1):
            res.error = f"replay: {(r.stdout + r.stderr).strip().splitlines()[-1:]}"
    return res
