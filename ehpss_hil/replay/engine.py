"""The replay engine (``ehpss-hil replay LOG [--mode M]``, :mod:`ehpss_hil.commands.replay`):
the logged sensor frames through the controller, offline.

Any log python-can reads: candump ``-L`` (ours, ``candump -L`` of can-utils, rotated sets),
``.asc``, ``.blf`` and the rest (:func:`~ehpss_hil.canlog.reader.read_frames`), streamed. The
frames are taken in receive-time order through a bounded reorder window
(:class:`~ehpss_hil.canlog.order.TimeOrder`: a file out of time order is one line, exit 2) and
grouped into the daemon's cycles by content: each VALVE_CMD closes one, and the sensor frames it
used are those up to the SENSOR_POS whose E2E counter it echoes (``SensorCounterEcho``); CycleCount
gaps are periods the daemon slept through, or, in a lockstep log, commands lost on the bus
(``--gaps``). Each cycle runs through the same :class:`~ehpss_hil.driver.ControllerDriver` as the
daemon: superseded samples observed, the sample count from the E2E counter, catch-up, fail-safe and
the reset after it, the ±1 A clip. From the first VALVE_CMD with ``Enable = 1`` (the daemon's first
ACTIVE cycle, reference sample 0) the replayed current, quantized by the DBC
(:meth:`FrameCodec.quantize`), is compared with the logged setpoint. Same configuration →
bit-identical; otherwise the first divergence is printed (exit 1). A logged ``Enable = 0`` after
the start is the daemon's fail-safe (FAULT, ``failsafe: zero``): not stepped, the reference runs
on, and the controller is reset when commands are enabled again. The ``oracle`` mode needs the true
faults and is not replayable.

Configuration: ``--config controller.yaml`` (mode, rate, reference, tuning, params), else the
sidecar (``config``/``scenario``/``reference``, ``rate_hz``, ``mode``), else the defaults; ``--mode``
overrides the mode. ``failsafe: hold`` cycles (the last command repeated with Enable = 1) cannot be
told from the log and show as divergences.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import can

from ..canlog import BadLines, read_sidecar
from ..canlog.order import TimeOrder
from ..canlog.reader import read_frames, resolve_log
from ..codec import Decoded, FrameCodec
from ..config import SetpointPolicy, load_controller_config
from ..control.registry import DAEMON_MODES, make_controller
from ..control.sampleclock import RESYNC_SAMPLES
from ..control.tuning import ControlTuning
from ..driver import ControllerDriver
from ..errors import EhpssError
from ..physics.load import load_params
from ..physics.params import Params
from ..report.logdata import MODE_NAMES
from ..report.logmeta import run_info
from ..runtime.foreign import SetpointGate
from ..runtime.frameio import limit_sensor_rate
from ..scenario import Reference, ReferenceBlocks, load_scenario


class ReplayError(EhpssError, RuntimeError):
    """The replay cannot run (no controller library, nothing to replay)."""


@dataclass
class ReplaySetup:
    """What the controller is built from (SI: ``ts_s`` in s)."""

    mode: str
    ts_s: float
    reference: Reference
    tuning: ControlTuning
    params: Params
    source: str
    #: which SETPOINT frames the daemon let override x_d
    setpoint: SetpointPolicy = field(default_factory=SetpointPolicy)


@dataclass
class Divergence:
    """One cycle where the replayed command differs from the logged one (A)."""

    cycle: int
    frame_number: int
    logged_a: float
    replayed_a: float
    logged_enable: bool
    replayed_enable: bool


@dataclass
class ReplayResult:
    """Outcome of a replay: cycles compared, fail-safe cycles skipped (logged ``Enable = 0``),
    divergent cycles, the first few divergences."""

    setup: ReplaySetup
    cycles: int = 0
    failsafe_cycles: int = 0
    #: periods the daemon skipped (CycleCount gaps), stepped without a frame
    skipped_periods: int = 0
    divergent: int = 0
    max_abs_diff_a: float = 0.0
    first: list[Divergence] = field(default_factory=list)
    #: log lines that are no frame (skipped)
    bad_lines: BadLines = field(default_factory=BadLines)
    #: frames further back in time than the reorder window (the wall clock was set back)
    clock_steps_back: int = 0

    @property
    def identical(self) -> bool:
        """True when every replayed command equals the logged one bit for bit."""
        return self.cycles > 0 and self.divergent == 0


def _logged_mode(log: Path) -> str | None:
    codec = FrameCodec()
    mode = None
    status_id = codec.can_id("CTRL_STATUS")
    for msg in read_frames(log, bad=BadLines()):  # counted by the replay itself
        if msg.arbitration_id == status_id:
            d = codec.classify(msg)
            if d.values is not None and d.verdict.usable:
                mode = MODE_NAMES.get(int(d.values["Mode"]))
    return mode


def resolve_setup(log: Path, mode: str | None, config: Path | None, scenario: Path | None) -> ReplaySetup:
    """The controller configuration of a logged run (see the module docstring)."""
    if config is not None:
        cfg = load_controller_config(config)
        return ReplaySetup(
            mode or cfg.mode,
            1.0 / cfg.rate_hz,
            cfg.reference,
            cfg.tuning,
            load_params(cfg.params or None),
            str(config),
            cfg.setpoint,
        )
    info = run_info(
        read_sidecar(log), log.parent, load_scenario(scenario) if scenario is not None else None, log
    )
    logged = mode or _logged_mode(log) or info.mode or "mmac"
    return ReplaySetup(
        logged,
        info.ts_s or 1e-3,
        info.reference or Reference(),
        info.tuning or ControlTuning(),
        load_params(info.params_path),
        ", ".join(info.sources) or "defaults",
        info.setpoint or SetpointPolicy(),
    )


def _make(setup: ReplaySetup) -> Any:
    if setup.mode not in DAEMON_MODES:
        raise ReplayError(
            f"mode {setup.mode!r} is not replayable (it needs the true faults); "
            f"choose one of {', '.join(DAEMON_MODES)}"
        )
    return make_controller(setup.mode, setup.params, setup.ts_s, setup.tuning, setup.reference)


class Replayer:
    """The daemon's cycles rebuilt from a log, each run through the one controller driver.

    Frames are taken in receive-time order (the order the daemon drained them, whatever order a
    logger wrote them in). Each VALVE_CMD closes a cycle: the sensor frames it used are those up
    to the SENSOR_POS whose E2E counter it echoes (``SensorCounterEcho``) — a frame received
    after the daemon's drain but before its command waits for the next cycle. CycleCount gaps are
    periods the daemon slept through (realtime logs: stepped without data before the cycle's
    frames, as ``ControllerLoop.catch_up`` does) or, in a lockstep log (``lost_commands``),
    commands lost on the bus after cycles that ran on their own sample.
    """

    def __init__(self, setup: ReplaySetup, keep: int, lost_commands: bool) -> None:
        self.ctrl = _make(setup)
        self.driver = ControllerDriver(self.ctrl, ReferenceBlocks(setup.reference, setup.ts_s).at)
        self.codec = FrameCodec()
        limit_sensor_rate(self.codec, setup.params.plant.piston_speed_max_m_s, setup.ts_s)
        self.setpoints = SetpointGate(setup.setpoint)
        self.res = ReplayResult(setup)
        self.keep = keep
        self.ts = setup.ts_s
        self.lost_commands = lost_commands
        self.started = False
        self.in_failsafe = False
        self.cycle_count = 0
        #: usable sensor and SETPOINT frames not yet taken by a cycle, in receive order
        self.pending: list[Decoded] = []
        self._names = {self.codec.can_id(n): n for n in ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD", "SETPOINT")}

    def frame(self, msg: Any, number: int) -> None:
        """One frame, in receive-time order."""
        name = self._names.get(msg.arbitration_id)
        if name is None:
            return
        d = self.codec.classify(msg)
        if d.values is None or not d.verdict.usable:
            return
        v, t = d.values, float(msg.timestamp)
        if name != "VALVE_CMD":
            self.pending.append(d)
        elif self.started or v["Enable"]:
            cc = int(v["CycleCount"])
            gap = 0 if not self.started else (cc - self.cycle_count - 1) % 65536
            self.started = True
            self.cycle_count = cc
            self.command(
                float(v["CurrentSetpoint"]), bool(v["Enable"]), int(v["SensorCounterEcho"]), t, number, gap
            )
        else:  # before the daemon's first ACTIVE cycle (CONFIGURED: nothing is stepped)
            self.feed(self._leading_non_position())
            self.driver.idle_cycle()

    # ---- which frames a cycle took ------------------------------------------------------------
    def _leading_non_position(self) -> int:
        return next((i for i, r in enumerate(self.pending) if r.name == "SENSOR_POS"), len(self.pending))

    def _split(self, echo: int) -> int:
        """How many pending frames the cycle that echoes ``echo`` took: up to the last pending
        SENSOR_POS with that counter and the SENSOR_AUX after it, before the next SENSOR_POS;
        none of the SENSOR_POS frames when none has it (a cycle without a fresh sample)."""
        last = None
        for i, r in enumerate(self.pending):
            if r.name == "SENSOR_POS" and r.counter == echo:
                last = i
        if last is None:
            return self._leading_non_position()
        n = last + 1
        while n < len(self.pending) and self.pending[n].name != "SENSOR_POS":
            n += 1
        return n

    def _before(self, t_s: float) -> int:
        """How many pending frames were received before ``t_s`` (s)."""
        return next((i for i, r in enumerate(self.pending) if r.timestamp_s >= t_s), len(self.pending))

    def feed(self, n: int) -> None:
        """The first ``n`` pending frames, as the daemon's drain hands them to the driver (the
        daemon's SETPOINT gate, with x_d as the daemon had it then)."""
        for d in self.pending[:n]:
            self.driver.take(d, self.setpoints.admit)
        del self.pending[:n]

    # ---- cycles -----------------------------------------------------------------------------
    def _gap(self, periods: int, t_s: float) -> None:
        """CycleCount gap before the command at ``t_s`` (see the class docstring)."""
        self.res.skipped_periods += periods
        if self.lost_commands:
            for i in range(periods):  # the cycle ran on its own sample; its command was lost
                self.feed(self._before(t_s - (periods - i) * self.ts))
                if self.in_failsafe:
                    self.driver.failsafe_cycle()
                else:
                    self.driver.step()
            return
        if self.in_failsafe or periods > RESYNC_SAMPLES:
            self.driver.k += periods
            return
        self.driver.catch_up(periods)

    def command(
        self, logged_a: float, logged_en: bool, echo: int, t_s: float, number: int, gap: int = 0
    ) -> None:
        """A logged VALVE_CMD: the cycle it closes, replayed and compared."""
        if gap:
            self._gap(gap, t_s)
        self.feed(self._split(echo))
        drv = self.driver
        k = drv.k
        if not logged_en:  # the daemon's fail-safe (FAULT): no step, the reference runs on
            self.res.failsafe_cycles += 1
            self.in_failsafe = True
            drv.failsafe_cycle()
            return
        if self.in_failsafe:  # FAULT → ACTIVE: the daemon resets the controller
            drv.restart()
            self.in_failsafe = False
        cur, enable = drv.step()
        q = self.codec.quantize("VALVE_CMD", {"CurrentSetpoint": cur})["CurrentSetpoint"]
        self.res.cycles += 1
        if q != logged_a or bool(enable) != logged_en:
            self.res.divergent += 1
            self.res.max_abs_diff_a = max(self.res.max_abs_diff_a, abs(q - logged_a))
            if len(self.res.first) < self.keep:
                self.res.first.append(Divergence(k, number, logged_a, q, logged_en, enable))


def _is_lockstep_log(side: dict[str, Any] | None) -> bool:
    """A log written by the lockstep simulator (no overruns: a CycleCount gap is lost commands)."""
    return bool(side) and "lockstep" in str(side.get("tool", ""))  # type: ignore[union-attr]


def replay_log(
    path: str | Path,
    mode: str | None = None,
    config: Path | None = None,
    scenario: Path | None = None,
    keep: int = 5,
    gaps: str = "auto",
) -> ReplayResult:
    """Replay a log through the controller; see the module docstring. ``gaps``: ``overrun``,
    ``lost`` or ``auto`` (see :class:`Replayer`)."""
    log = resolve_log(path)
    setup = resolve_setup(log, mode, config, scenario)
    lost = gaps == "lost" or (gaps == "auto" and _is_lockstep_log(read_sidecar(log)))
    r = Replayer(setup, keep, lost)
    timeline: TimeOrder[tuple[int, can.Message]] = TimeOrder(log)
    for number, msg in enumerate(read_frames(log, bad=r.res.bad_lines), start=1):
        for n, m in timeline.push(msg.timestamp, (number, msg)):  # receive time, bounded window
            r.frame(m, n)
    for n, m in timeline.drain():
        r.frame(m, n)
    r.res.clock_steps_back = timeline.behind
    if r.res.cycles == 0:
        raise ReplayError(f"{log}: no VALVE_CMD with Enable=1: nothing to compare")
    return r.res
