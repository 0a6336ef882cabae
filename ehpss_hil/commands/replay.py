"""``ehpss-hil replay LOG [--mode M]``: the logged sensor frames through the controller, offline.

The log is read in file order (the logging process's causal order: a daemon logs each received
frame when it drains it and each VALVE_CMD when it sends it). Per logged VALVE_CMD, from the
first one with ``Enable = 1`` (the daemon's first ACTIVE cycle, reference sample 0): the newest
usable SENSOR_POS/SENSOR_AUX values since the previous command form the Measurement (``fresh``
when a SENSOR_POS arrived), ``x_d`` is the reference at that sample (or a SETPOINT override), the
controller steps once, and its current — clipped to ±1 A and quantized by the DBC
(:meth:`FrameCodec.quantize`) — is compared with the logged setpoint. Same configuration →
bit-identical; otherwise the first divergence is printed (exit 1). A logged ``Enable = 0`` after
the start is the daemon's fail-safe (FAULT, ``failsafe: zero``): not stepped, the reference runs
on, and the controller is reset when commands are enabled again (as the daemon does).

Configuration: ``--config controller.yaml`` (mode, rate, reference, tuning, params), else the
sidecar (``config``/``scenario``/``reference``, ``rate_hz``, ``mode``), else the defaults; ``--mode``
overrides the mode. ``failsafe: hold`` cycles (the last command repeated with Enable = 1) cannot be
told from the log and show as divergences.
"""

from __future__ import annotations

import argparse
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..canlog import BadLines, read_log, read_sidecar
from ..canlog.reader import resolve_log
from ..codec import FrameCodec, SampleCount
from ..config import SetpointPolicy, load_controller_config
from ..control.base import HeldSample, Measurement, hold_sample, observe_held
from ..control.sampleclock import RESYNC_SAMPLES
from ..control.tuning import ControlTuning
from ..errors import EhpssError
from ..physics.params import Params, load_params
from ..report.logdata import MODE_NAMES
from ..report.logmeta import run_info
from ..runtime.foreign import SetpointGate
from ..runtime.frameio import limit_sensor_rate
from ..scenario import Reference, ReferenceBlocks, load_scenario

NAME = "replay"


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

    @property
    def identical(self) -> bool:
        """True when every replayed command equals the logged one bit for bit."""
        return self.cycles > 0 and self.divergent == 0


def add_arguments(p: argparse.ArgumentParser) -> None:
    """Options of ``ehpss-hil replay``."""
    p.add_argument("log", type=Path, help="candump -L log (or its directory)")
    p.add_argument("--mode", default=None, help="controller mode (default: the logged one)")
    p.add_argument("--config", type=Path, default=None,
                   help="controller.yaml the run used (reference, tuning, params, rate)")
    p.add_argument("--scenario", type=Path, default=None,
                   help="scenario YAML for the reference and sample time")
    p.add_argument("--show", type=int, default=5, help="divergences to print (default 5)")


def _logged_mode(log: Path) -> str | None:
    codec = FrameCodec()
    mode = None
    status_id = codec.can_id("CTRL_STATUS")
    for msg in read_log(log, bad=BadLines()):  # counted by the replay itself
        if msg.arbitration_id == status_id:
            d = codec.classify(msg)
            if d.values is not None and d.verdict.usable:
                mode = MODE_NAMES.get(int(d.values["Mode"]))
    return mode


def resolve_setup(log: Path, mode: str | None, config: Path | None,
                  scenario: Path | None) -> ReplaySetup:
    """The controller configuration of a logged run (see the module docstring)."""
    if config is not None:
        cfg = load_controller_config(config)
        return ReplaySetup(mode or cfg.mode, 1.0 / cfg.rate_hz, cfg.reference, cfg.tuning,
                           load_params(cfg.params or None), str(config), cfg.setpoint)
    info = run_info(read_sidecar(log), log.parent,
                    load_scenario(scenario) if scenario is not None else None, log)
    logged = mode or _logged_mode(log) or info.mode or "mmac"
    return ReplaySetup(logged, info.ts_s or 1e-3, info.reference or Reference(),
                       info.tuning or ControlTuning(), load_params(info.params_path),
                       ", ".join(info.sources) or "defaults", info.setpoint or SetpointPolicy())


def _make(setup: ReplaySetup) -> Any:
    from ..control.registry import make_controller

    return make_controller(setup.mode, setup.params, setup.ts_s, setup.tuning, setup.reference)


class _Replayer:
    """The per-frame state machine of one replay."""

    def __init__(self, setup: ReplaySetup, keep: int) -> None:
        self.ctrl = _make(setup)
        self.codec = FrameCodec()
        limit_sensor_rate(self.codec, setup.params.plant.piston_speed_max_m_s, setup.ts_s)
        self.setpoints = SetpointGate(setup.setpoint)
        self.res = ReplayResult(setup)
        self.keep = keep
        self.meas = Measurement()
        self.fresh = False
        self.started = False
        self.in_failsafe = False
        self.override: float | None = None
        self.ts = setup.ts_s
        self.ref = setup.reference
        self._xd = ReferenceBlocks(self.ref, self.ts)
        self.k = 0
        self.cycle_count = 0
        self.prev = Measurement()
        self._pos_counter = 0  # E2E counter of the newest usable SENSOR_POS
        self._samples = SampleCount()  # sensor samples between those stepped on (as the daemon)
        self._superseded: list[HeldSample] = []
        self._scratch = Measurement()
        self._names = {self.codec.can_id(n): n for n in
                       ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD", "SETPOINT")}

    def _snapshot(self) -> None:
        p, m = self.prev, self.meas
        p.position_m, p.spool_m = m.position_m, m.spool_m
        p.coil_current_a, p.load_pressure_pa = m.coil_current_a, m.load_pressure_pa

    def x_d(self, k: int) -> float:
        """Reference at sample k (m)."""
        return self._xd.at(k)

    def frame(self, msg: Any, number: int) -> None:
        name = self._names.get(msg.arbitration_id)
        if name is None:
            return
        d = self.codec.classify(msg)
        if d.values is None or not d.verdict.usable:
            return
        v, m = d.values, self.meas
        if name == "SENSOR_POS":
            if self.fresh:  # a burst: the daemon keeps the older sample for ``observe``
                self._superseded.append(hold_sample(m, self._pos_counter))
            m.position_m, m.spool_m, self.fresh = float(v["Position"]), float(v["Spool"]), True
            self._pos_counter = msg.data[1] & 0x0F
        elif name == "SENSOR_AUX":
            m.coil_current_a, m.load_pressure_pa = float(v["CoilCurrent"]), float(v["LoadPressure"])
        elif name == "SETPOINT":
            x_d = self.x_d(self.k) if self.override is None else self.override
            if self.setpoints.admit(bool(v["Override"]), float(v["Position"]), x_d):
                self.override = float(v["Position"]) if v["Override"] else None
        elif self.started or v["Enable"]:
            cc = int(v["CycleCount"])
            gap = 0 if not self.started else (cc - self.cycle_count - 1) % 65536
            self.started = True
            self.cycle_count = cc
            self.command(float(v["CurrentSetpoint"]), bool(v["Enable"]), number, gap)
        else:  # before the daemon's first ACTIVE cycle (CONFIGURED: nothing is stepped)
            self.fresh = False
            self._superseded.clear()

    def _catch_up(self, periods: int) -> None:
        """Periods the daemon skipped (a CycleCount gap): stepped without a frame on the values
        of the previous command, as ``ControllerLoop.catch_up`` does — never more than
        ``RESYNC_SAMPLES`` (beyond, the daemon went to fail-safe, LOOP_OVERRUN, without
        stepping; its next commands are Enable 0 and the law is reset after them)."""
        self.res.skipped_periods += periods
        if self.in_failsafe or periods > RESYNC_SAMPLES:
            self.k += periods
            return
        m = self.prev
        m.fresh = m.command_sent = False
        for _ in range(periods):
            m.reference_m = self.override if self.override is not None else self.x_d(self.k)
            self.ctrl.step(m)
            self.k += 1
        m.command_sent = True

    def command(self, logged_a: float, logged_en: bool, number: int, gap: int = 0) -> None:
        self._catch_up(gap)
        k = self.k
        self.k += 1
        if not logged_en:  # the daemon's fail-safe (FAULT): no step, the reference runs on
            self.res.failsafe_cycles += 1
            self.in_failsafe = True
            self.fresh = False
            self._superseded.clear()
            self._snapshot()
            return
        if self.in_failsafe:  # FAULT → ACTIVE: the daemon resets the controller
            self.ctrl.reset()
            self.in_failsafe = False
            self._samples.reset()
        observe_held(self.ctrl.observe, self._superseded, self._samples.take, self._scratch)
        m = self.meas
        m.reference_m = self.override if self.override is not None else self.x_d(k)
        m.fresh = self.fresh
        if self.fresh:
            m.samples = self._samples.take(self._pos_counter)
        cmd = self.ctrl.step(m)
        self._snapshot()
        cur = cmd.current_a if math.isfinite(cmd.current_a) else 0.0
        cur = max(-1.0, min(1.0, cur))
        q = self.codec.quantize("VALVE_CMD", {"CurrentSetpoint": cur})["CurrentSetpoint"]
        self.fresh = False
        self.res.cycles += 1
        if q != logged_a or bool(cmd.enable) != logged_en:
            self.res.divergent += 1
            self.res.max_abs_diff_a = max(self.res.max_abs_diff_a, abs(q - logged_a))
            if len(self.res.first) < self.keep:
                self.res.first.append(Divergence(k, number, logged_a, q, logged_en,
                                                 bool(cmd.enable)))


def replay_log(path: str | Path, mode: str | None = None, config: Path | None = None,
               scenario: Path | None = None, keep: int = 5) -> ReplayResult:
    """Replay a log through the controller; see the module docstring."""
    log = resolve_log(path)
    setup = resolve_setup(log, mode, config, scenario)
    r = _Replayer(setup, keep)
    for number, msg in enumerate(read_log(log, bad=r.res.bad_lines), start=1):
        r.frame(msg, number)
    if r.res.cycles == 0:
        raise ReplayError(f"{log}: no VALVE_CMD with Enable=1: nothing to compare")
    return r.res


def describe(d: Divergence, ts_s: float) -> str:
    """One line for a divergence."""
    lsb = 2e-7
    return (f"cycle {d.cycle} (t = {d.cycle * ts_s:.4f} s, frame #{d.frame_number} of the log): "
            f"logged {d.logged_a:+.7f} A (enable {int(d.logged_enable)}), replayed "
            f"{d.replayed_a:+.7f} A (enable {int(d.replayed_enable)}), "
            f"diff {(d.replayed_a - d.logged_a) / lsb:+.0f} LSB")


def run(args: argparse.Namespace) -> int:
    """Replay and print the verdict: 0 identical, 1 diverged."""
    res = replay_log(args.log, args.mode, args.config, args.scenario, args.show)
    s = res.setup
    print(f"replayed {res.cycles} cycles with mode {s.mode} at Ts = {s.ts_s * 1e3:g} ms "
          f"(config from {s.source})")
    if res.bad_lines.count:
        print(f"{res.bad_lines.text()} (not frame lines: a cut last line or garbage)")
    if res.skipped_periods:
        print(f"{res.skipped_periods} periods skipped by the daemon's overruns (CycleCount gaps) "
              "stepped without a frame, as the daemon does")
    if res.failsafe_cycles:
        print(f"{res.failsafe_cycles} fail-safe cycles (logged Enable=0) skipped; the controller "
              "is reset when they end, as the daemon does")
    if res.identical:
        print("identical: every replayed VALVE_CMD equals the logged one bit for bit")
        return 0
    print(f"DIVERGED in {res.divergent} of {res.cycles} cycles (max |diff| "
          f"{res.max_abs_diff_a:.3g} A); first divergence:")
    for d in res.first:
        print("  " + describe(d, s.ts_s))
    return 1
