"""kill -9 and SIGTERM of either process during a realtime run, with a separate bus logger.

Each trial runs in its own private namespace: bus logger, emulator (fault-free scenario) and
controller (``configs/controller.yaml`` with ``watchdog.timeout_cycles`` from the config, auto
recovery on so that a host stall before the kill does not end the run in FAULT).

kill -9 (victim chosen per trial, at a random moment 0.2–1.5 s after the controller went
ACTIVE): the survivor must reach its safe state within its configured count — controller: 0 A
with Enable 0 within ``timeout_cycles`` executed cycles of its last usable sensor frame;
emulator: CmdTimeout within ``command_timeout_s × rate`` periods of the last accepted command and
0 A applied from then on (SENSOR_AUX CoilCurrent echo). The survivor is then stopped with
SIGTERM (exit 0) and its candump log must hold every frame the logger saw from the victim (from
the survivor's first one to the kill) and every frame it sent itself: none missing, none extra,
no partial or malformed line.

SIGTERM (one process during the run, then the other): exit 0 for both, the controller's last
VALVE_CMD on the bus is 0 A with Enable 0 and reached the emulator, both logs complete against
the logger's and their sidecars closed with nothing dropped.
"""

from __future__ import annotations

import json
import random
import time
from dataclasses import dataclass, field
from pathlib import Path

from firmware_sim.process import OWN_FRAMES as EMU_FRAMES

from ..canlog import read_sidecar
from ..codec import FrameCodec
from ..runtime.controller_loop import OWN_FRAMES as CTRL_FRAMES
from ..schema import load_yaml
from .logcheck import (
    LogFile,
    WatchdogAudit,
    audit_watchdog,
    compare,
    controller_cycles,
    cycles_to_safe,
    decode_own,
    emulator_safe,
    last_status,
    read_candump,
)
from .procs import CONTROLLER_YAML, EMULATOR_YAML, READY, Child, Trial

PROCS = ("controller", "emulator")
_CODEC = FrameCodec()
_IDS = {
    "controller": {_CODEC.can_id(n) for n in CTRL_FRAMES},
    "emulator": {_CODEC.can_id(n) for n in EMU_FRAMES},
}


def configured_limits() -> dict[str, int]:
    """The safe-state limits from the shipped configs: controller ``watchdog.timeout_cycles``
    (cycles), emulator ``command_timeout_s × rate_hz`` (periods)."""
    c, e = load_yaml(CONTROLLER_YAML) or {}, load_yaml(EMULATOR_YAML) or {}
    return {
        "controller": int((c.get("watchdog") or {}).get("timeout_cycles", 3)),
        "emulator": max(1, round(float(e.get("command_timeout_s", 0.010)) * float(e.get("rate_hz", 1000.0)))),
    }


@dataclass
class LogAudit:
    """One process's log against the bus logger's: ``rx_*`` the other process's frames it
    received, ``tx_*`` the frames it sent."""

    rx_missing: int = 0
    rx_extra: int = 0
    tx_missing: int = 0
    tx_extra: int = 0
    frames: int = 0
    bad_lines: int = 0
    complete: bool = True

    @property
    def ok(self) -> bool:
        """Nothing missing, nothing extra, no bad or partial line."""
        return (
            self.rx_missing == self.rx_extra == self.tx_missing == self.tx_extra == self.bad_lines == 0
            and self.complete
            and self.frames > 0
        )


def audit_log(proc: str, own: LogFile, bus: LogFile, other_ended_first: bool = True) -> LogAudit:
    """``proc``'s log ``own`` against the logger's ``bus``. ``other_ended_first``: the other
    process stopped before this one, so every frame it sent must be in ``own``; else ``own``
    must hold them up to the last one it logged (it stopped listening at its exit)."""
    other = "emulator" if proc == "controller" else "controller"
    rx = compare(own.only(_IDS[other]), bus.only(_IDS[other]), to_end=other_ended_first)
    tx = compare(own.only(_IDS[proc]), bus.only(_IDS[proc]))
    return LogAudit(rx.missing, rx.extra, tx.missing, tx.extra, len(own.frames), own.bad_lines, own.complete)


@dataclass
class KillResult:
    """One kill -9 trial. ``safe`` in the survivor's own cycles/periods (None: never)."""

    trial: int
    victim: str
    at_s: float
    limit: int
    safe: int | None = None
    #: emulator survivor: periods until 0 A was applied (CoilCurrent echo)
    zero_current: int | None = None
    #: controller survivor: CTRL_STATUS state/reason before its shutdown status
    status: tuple[str, str] | None = None
    #: controller survivor: its watchdog trips against real timeouts over the whole run
    audit: WatchdogAudit | None = None
    survivor_exit: int | None = None
    log: LogAudit = field(default_factory=LogAudit)
    error: str = ""

    @property
    def survivor(self) -> str:
        return "emulator" if self.victim == "controller" else "controller"

    @property
    def ok(self) -> bool:
        """Safe in time, clean exit, complete log."""
        in_time = self.safe is not None and self.safe <= self.limit
        if self.survivor == "emulator":
            in_time = in_time and self.zero_current is not None and self.zero_current <= self.limit
        elif self.audit is None or self.audit.spurious or self.audit.missed:
            return False
        return not self.error and in_time and self.survivor_exit == 0 and self.log.ok


def _start(t: Trial) -> tuple[Child, dict[str, Child]]:
    """Bus logger, emulator, then the controller (the config's watchdog, auto recovery on)."""
    logger = t.logger()
    emu = t.emulator({})
    if not emu.wait_text(READY["emulator"]):
        raise RuntimeError(f"emulator did not start: {emu.text()[-500:]}")
    ctl = t.controller({"watchdog.auto_recover": True})
    if not ctl.wait_text(READY["controller"]):
        raise RuntimeError(f"controller did not go ACTIVE: {ctl.text()[-500:]}")
    return logger, {"controller": ctl, "emulator": emu}


_SAFE_LINE = {"controller": "-> FAULT", "emulator": "no valid VALVE_CMD for"}


def kill_trial(out: Path, trial: int, victim: str, rng: random.Random) -> KillResult:
    """One kill -9 of ``victim`` at a random moment; measure the survivor."""
    limits = configured_limits()
    res = KillResult(
        trial, victim, rng.uniform(0.2, 1.5), limits["emulator" if victim == "controller" else "controller"]
    )
    surv = res.survivor
    try:
        with Trial(out) as t:
            logger, procs = _start(t)
            time.sleep(res.at_s)
            seen = procs[surv].text().count(_SAFE_LINE[surv])
            procs[victim].kill9()
            end = time.monotonic() + 5.0  # (no new line when a host stall had tripped it)
            while procs[surv].text().count(_SAFE_LINE[surv]) <= seen and time.monotonic() < end:
                time.sleep(0.02)
            time.sleep(0.1)
            res.survivor_exit = procs[surv].terminate()
            logger.terminate()
    except (RuntimeError, OSError) as exc:
        res.error = str(exc)
        return res
    own, bus = read_candump(out / f"{surv}.log"), read_candump(out / "logger.log")
    res.log = audit_log(surv, own, bus)
    if surv == "controller":
        cycles = controller_cycles(own)
        res.safe = cycles_to_safe(cycles)
        res.status = last_status(own)
        res.audit = audit_watchdog(cycles, res.limit)
    else:
        es = emulator_safe(own)
        res.safe, res.zero_current = es.periods_to_timeout, es.periods_to_zero_current
    return res


@dataclass
class TermResult:
    """One SIGTERM trial: ``first`` got SIGTERM during the run, then the other."""

    trial: int
    first: str
    at_s: float
    exits: dict[str, int | None] = field(default_factory=dict)
    #: the controller's last VALVE_CMD on the bus: (CurrentSetpoint A, Enable)
    last_command: tuple[float, int] | None = None
    #: that command is also the last one in the emulator's log (it reached the emulator)
    command_delivered: bool = False
    logs: dict[str, LogAudit] = field(default_factory=dict)
    #: sidecar status "closed" (the writer flushed and closed the file)
    closed: dict[str, bool] = field(default_factory=dict)
    #: lines the writer dropped (sidecar counts)
    dropped: dict[str, int] = field(default_factory=dict)
    error: str = ""

    @property
    def ok(self) -> bool:
        """Both exit 0, zero current last, logs complete, closed, nothing dropped."""
        return (
            not self.error
            and all(v == 0 for v in self.exits.values())
            and len(self.exits) == 2
            and self.last_command == (0.0, 0)
            and all(a.ok for a in self.logs.values())
            and all(self.closed.values())
            and not any(self.dropped.values())
            and (self.first == "emulator" or self.command_delivered)
        )


def term_trial(out: Path, trial: int, first: str, rng: random.Random) -> TermResult:
    """SIGTERM ``first`` at a random moment, then the other process, then the logger."""
    res = TermResult(trial, first, rng.uniform(0.2, 1.5))
    try:
        with Trial(out) as t:
            logger, procs = _start(t)
            time.sleep(res.at_s)
            res.exits[first] = procs[first].terminate()
            time.sleep(0.1)
            second = "emulator" if first == "controller" else "controller"
            res.exits[second] = procs[second].terminate()
            logger.terminate()
    except (RuntimeError, OSError) as exc:
        res.error = str(exc)
        return res
    bus = read_candump(out / "logger.log")
    cmd = _CODEC.can_id("VALVE_CMD")
    cmds = bus.only({cmd})
    if cmds:
        v = decode_own(_CODEC, "VALVE_CMD", cmds[-1])
        res.last_command = (float(v["CurrentSetpoint"]), int(v["Enable"]))
    for p in PROCS:
        own = read_candump(out / f"{p}.log")
        res.logs[p] = audit_log(p, own, bus, other_ended_first=p != first)
        side = read_sidecar(out / f"{p}.log") or {}
        res.closed[p] = side.get("status") == "closed"
        res.dropped[p] = int((side.get("counts") or {}).get("dropped", -1))
        if p == "emulator" and cmds:
            res.command_delivered = own.only({cmd})[-1:] == cmds[-1:]
    return res


def summary_json(out: Path, proc: str) -> dict[str, object]:
    """A process's ``--summary-json`` from a trial directory (empty when absent)."""
    try:
        data = json.loads((out / f"{proc}.json").read_text())
    except (OSError, ValueError):
        return {}
    return data if isinstance(data, dict) else {}
