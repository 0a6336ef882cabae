"""The emulator process's loop and I/O around :class:`~firmware_sim.emulation.PlantEmulation`.

Realtime, each period k (fixed deadline grid): drain RX without blocking → the newest valid
VALVE_CMD is held (invalid ones are counted by the codec and ignored; FAULT_INJECT applied only
when enabled) → the command-timeout count → measure y[k] → SENSOR_POS + SENSOR_AUX (unless the
scenario's seeded loss drops them) → PLANT_TRUTH (truth on) → advance the plant one period with the
held current → PLANT_FAULTS on change and at 10 Hz (truth on) → heartbeat. The network itself is
the transport delay: a command computed from y[k−1] arrives during period k−1 and is applied
over [k, k+1).

Lockstep: y[0] is sent at start; each received VALVE_CMD frame completes one period (an invalid
one counts as a missing command, so a corrupted frame cannot stall the plant); the plant then
advances with the command ``transport_delay_samples`` periods old (the scenario's), exactly as
the offline simulation; a lost sensor frame (seeded) means no answer is awaited for that period.
"""

from __future__ import annotations

import logging
import time
from collections import deque
from dataclasses import dataclass
from typing import Any

import can

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.emulation import PlantEmulation, SensorSample
from ehpss_hil.errors import InjectError, PlantStepError
from ehpss_hil.physics.faults import FaultState
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.runtime.stats import LoopStats, peak_rss_bytes

from .command_hold import CommandHold
from .commanders import CommanderCheck
from .inject import InjectStatus, ack_values, check_inject
from .periods import run_periods

log = logging.getLogger("firmware_sim")

#: frames this process transmits (their echoes on udp_multicast are dropped on receive)
OWN_FRAMES = ("SENSOR_POS", "SENSOR_AUX", "PLANT_TRUTH", "PLANT_FAULTS", "FAULT_INJECT_ACK", "HEARTBEAT_EMU")
#: a second VALVE_CMD transmitter (commanders.py): frames looked back over, foreign frames in
#: them that make a conflict, the largest CycleCount step of one controller (a catch-up)
COMMANDER_WINDOW = 100
COMMANDER_LIMIT = 10
COMMANDER_MAX_AHEAD = 2000
NMT_OPERATIONAL = 5
NMT_STOPPED = 4


@dataclass(frozen=True)
class EmulatorOptions:
    """Run options (from emulator.yaml and the command line). Times in s, rates in Hz."""

    command_timeout_s: float = 0.010
    truth: bool = False
    fault_inject: bool = False
    heartbeat_rate_hz: float = 10.0
    faults_rate_hz: float = 10.0
    lockstep_timeout_s: float = 5.0
    stats_capacity: int = 600_000


class EmulatorProcess:
    """One emulator instance on one bus (periods of ``emu.ts_s``)."""

    def __init__(self, emu: PlantEmulation, io: FrameIO, opts: EmulatorOptions) -> None:
        self.emu = emu
        self.io = io
        self.codec: FrameCodec = io.codec
        self.opts = opts
        rate_hz = 1.0 / emu.ts_s
        self.hold = CommandHold(max(1, round(opts.command_timeout_s * rate_hz)))
        self._id_cmd = self.codec.can_id("VALVE_CMD")
        self.commanders = CommanderCheck(COMMANDER_WINDOW, COMMANDER_LIMIT, COMMANDER_MAX_AHEAD)
        self._id_inject = self.codec.can_id("FAULT_INJECT")
        self._hb_every = max(1, round(rate_hz / opts.heartbeat_rate_hz))
        self._faults_every = max(1, round(rate_hz / opts.faults_rate_hz))
        self._bounds = {n: self.codec.signal_bounds(n) for n in ("SENSOR_POS", "SENSOR_AUX", "PLANT_TRUTH")}
        self.stats = LoopStats(opts.stats_capacity)
        self.periods = 0
        #: periods slept through by overruns, the plant advanced without frames (step_period)
        self.skipped_periods = 0
        self.lost_sensor = 0
        self.lost_cmd = 0
        self.clipped = 0
        self.inject_applied = 0
        self.inject_rejected = 0
        self.inject_ignored = 0
        #: why the plant stopped (an FMU's failed step), or "" while it runs
        self.plant_failure = ""
        self.applied_a = 0.0
        self._faults: FaultState = emu.faults
        #: the newest valid command among the frames drained before the first period
        self._early: tuple[float, bool] | None = None

    # ---- receive ----------------------------------------------------------------------------
    def _on_frame(self, msg: can.Message) -> tuple[float, bool] | bool | None:
        """Classify a consumed frame: VALVE_CMD → (setpoint, enable) or False; else None."""
        if msg.arbitration_id == self._id_cmd:
            d = self.codec.classify(msg)
            chk, was = self.commanders, self.commanders.conflict
            if d.verdict.usable and d.values is not None:
                cycle = d.values.get("CycleCount")  # a vendor command frame may have none
                in_order = cycle is None or chk.usable(int(cycle))
                cmd = (float(d.values["CurrentSetpoint"]), bool(d.values.get("Enable", 1)))
            else:
                if d.verdict in (Verdict.REPEATED, Verdict.WRONG_SEQUENCE):
                    chk.rejected_sequence()
                in_order, cmd = False, None
            if chk.conflict != was:
                if chk.conflict:
                    log.error(
                        "t=%.4f s: a second VALVE_CMD transmitter (%d foreign frames): "
                        "valve centred until one commander is left",
                        self.t_s,
                        chk.foreign,
                    )
                else:
                    log.warning("t=%.4f s: one VALVE_CMD commander again", self.t_s)
            return cmd if (in_order and cmd is not None and not chk.conflict) else False
        if msg.arbitration_id == self._id_inject:
            self._on_inject(msg)
        return None

    def _drain(self) -> tuple[float, bool] | None:
        """All pending frames; returns the newest valid command of them (or None)."""
        newest = None
        for msg in self.io.drain():
            r = self._on_frame(msg)
            if isinstance(r, tuple):
                newest = r
        return newest

    def _on_inject(self, msg: can.Message) -> None:
        """Apply a FAULT_INJECT when injection is on and it checks out; answer every one with a
        FAULT_INJECT_ACK saying what became of it (the monitor's page shows a refusal)."""
        d = self.codec.classify(msg)
        values = d.values if d.verdict.usable else None
        if not self.opts.fault_inject:
            self.inject_ignored += 1
            self.io.send("FAULT_INJECT_ACK", ack_values(InjectStatus.INJECTION_OFF, values))
            return
        status, change = check_inject(values) if values is not None else (InjectStatus.INVALID_FRAME, None)
        self.io.send("FAULT_INJECT_ACK", ack_values(status, values))
        if change is None:
            self.inject_rejected += 1
            log.warning("t=%.4f s: FAULT_INJECT rejected (%s, %s)", self.t_s, d.verdict.name, status.name)
            return
        if change:
            try:
                self.emu.inject(**change)
            except InjectError as exc:
                self.inject_rejected += 1
                log.warning("t=%.4f s: FAULT_INJECT rejected (%s)", self.t_s, exc)
                return
        else:
            self.emu.clear_injected()
        self.inject_applied += 1
        log.info("t=%.4f s: FAULT_INJECT %s", self.t_s, change or "clear")
        self._check_faults()

    # ---- transmit ---------------------------------------------------------------------------
    def _clip(self, name: str, values: dict[str, Any]) -> dict[str, Any]:
        b = self._bounds[name]
        for sig, v in values.items():
            lo, hi = b.get(sig, (None, None))  # a signal the profile's frame does not carry
            if lo is not None and v < lo:
                values[sig] = lo
                self.clipped += 1
            elif hi is not None and v > hi:
                values[sig] = hi
                self.clipped += 1
        return values

    def _send_sample(self, y: SensorSample) -> bool:
        """SENSOR_POS + SENSOR_AUX for y (unless lost) and PLANT_TRUTH; True when sent."""
        if self.opts.truth:
            self.io.send(
                "PLANT_TRUTH",
                self._clip(
                    "PLANT_TRUTH",
                    {
                        "Position": y.true_position_m,
                        "SpoolActual": y.true_spool_m,
                        "Stuck": int(y.faults.stuck),
                    },
                ),
            )
        if self.emu.frame_lost(0):  # lost on the way: the counters move on (receiver: a gap)
            self.lost_sensor += 1
            self._skip_sample()
            return False
        self.io.send_together(
            ("SENSOR_POS", self._clip("SENSOR_POS", {"Position": y.position_m, "Spool": y.spool_m})),
            (
                "SENSOR_AUX",
                self._clip(
                    "SENSOR_AUX",
                    {
                        "LoadPressure": y.load_pressure_pa,
                        "CoilCurrent": y.coil_current_a,
                        "ValveEnabled": int(self.hold.valve_enabled),
                        "CmdTimeout": int(self.hold.timed_out),
                        "CurrentSaturated": int(y.current_saturated),
                        "CommandConflict": int(self.commanders.conflict),
                    },
                ),
            ),
        )
        return True

    def _skip_sample(self) -> None:
        """A sensor sample not sent: the sensor frames' E2E counters move on over it."""
        self.codec.skip("SENSOR_POS")
        self.codec.skip("SENSOR_AUX")

    def _send_faults(self) -> None:
        f = self.emu.faults
        self.io.send(
            "PLANT_FAULTS",
            {"KLoe": min(f.k_loe, 6.5535), "KQ": min(f.k_q, 6.5535), "KDft": min(f.k_dft, 6.5535)},
        )

    def _check_faults(self) -> None:
        f = self.emu.faults
        if f != self._faults:
            old = self._faults
            diff = ", ".join(
                f"{k} {getattr(old, k)} -> {getattr(f, k)}"
                for k in f.__dataclass_fields__
                if getattr(old, k) != getattr(f, k)
            )
            log.info("t=%.4f s (k=%d): faults changed: %s", self.t_s, self.emu.k, diff)
            self._faults = f
            if self.opts.truth:
                self._send_faults()

    def _housekeeping(self, nmt_state: int = NMT_OPERATIONAL) -> None:
        """After the plant advanced: fault changes, periodic PLANT_FAULTS and heartbeat."""
        self._check_faults()
        self.periods += 1
        if self.opts.truth and self.periods % self._faults_every == 0:
            self._send_faults()
        if self.periods % self._hb_every == 0:
            self.io.send("HEARTBEAT_EMU", {"NmtState": nmt_state})

    @property
    def t_s(self) -> float:
        """Emulated time of the current sample (s)."""
        return self.emu.k * self.emu.ts_s

    # ---- one period -------------------------------------------------------------------------
    def _take_command(self, cmd: tuple[float, bool] | None) -> float:
        """Command-direction loss draw, hold update and timeout count; returns the setpoint (A)."""
        lost = self.emu.frame_lost(1)
        if cmd is not None:
            if lost:
                self.lost_cmd += 1
            else:
                self.hold.accept(*cmd)
        setpoint = self.hold.tick(self.t_s)
        return 0.0 if self.commanders.conflict else setpoint

    def step_period(self, skipped: int = 0) -> float:
        """One realtime period (no waiting); returns the current applied over it (A).

        ``skipped``: grid periods this process slept through (an overrun). The plant does not
        stop when its emulator is late: it advances over them with the held command (the one
        just drained) before this period's sample, so the plant stays on the wall clock (and so
        do the scenario's events). Their sensor samples are lost: nothing is sent for them, and
        the sensor frames' E2E counters move on, so the receiver sees how many samples passed
        (OK_SOME_LOST), as from a sensor that samples on its own clock."""
        newest = self._drain()
        if self._early is not None:
            newest, self._early = newest or self._early, None
        setpoint = self._take_command(newest)
        for _ in range(skipped):
            self.emu.measure()  # draws the sample's noise: the streams stay on the sample grid
            self._skip_sample()
            self.emu.advance(setpoint)
            self._check_faults()
            self.periods += 1
            self.skipped_periods += 1
        self._send_sample(self.emu.measure())
        self.applied_a = self.emu.advance(setpoint)
        self._housekeeping()
        self.io.idle()  # the log writer may run now, while this process sleeps
        return self.applied_a

    # ---- loops ------------------------------------------------------------------------------
    def _fail_safe(self, exc: PlantStepError) -> None:
        """The plant cannot advance (an FMU's step failed): no more sensor frames, so the
        controller's sensor watchdog takes its own fail-safe; a STOPPED heartbeat; the reason
        logged on one line and kept for the summary (``plant_failure``)."""
        self.plant_failure = str(exc)
        log.error("t=%.4f s: %s; emulator stopped (fail-safe: no more sensor frames)", self.t_s, exc)
        self.io.send("HEARTBEAT_EMU", {"NmtState": NMT_STOPPED})

    def run_realtime(self, stop: StopFlag, n_periods: int | None = None) -> bool:
        """Run on the deadline grid until ``stop`` or ``n_periods`` periods; False when the
        plant failed (fail-safe, :meth:`_fail_safe`)."""
        self.io.send("HEARTBEAT_EMU", {"NmtState": 0})  # CiA 301 boot-up
        # the frames queued since the bus opened (a running controller sends ~1000/s): handled
        # now, not in the first period, which they made several ms late — a stall right at the
        # controller's first samples, whose reference starts with them
        self._early = self._drain()
        try:
            run_periods(self.emu.ts_s, self.step_period, lambda: self.periods, self.stats, stop, n_periods)
        except PlantStepError as exc:
            self._fail_safe(exc)
            return False
        self._drain()  # classify + log what arrived since the last period (e.g. a final command)
        self.io.send("HEARTBEAT_EMU", {"NmtState": NMT_STOPPED})
        return True

    def _await_command(self, stop: StopFlag) -> tuple[bool, tuple[float, bool] | None]:
        """Lockstep: wait for the next VALVE_CMD frame → (arrived, valid command or None)."""
        deadline = time.monotonic() + self.opts.lockstep_timeout_s
        while not stop:
            left = deadline - time.monotonic()
            if left <= 0.0:
                return False, None
            msg = self.io.recv(min(left, 0.1))
            if msg is None:
                continue
            r = self._on_frame(msg)
            if r is not None:
                return True, (r if isinstance(r, tuple) else None)
        return False, None

    def run_lockstep(self, stop: StopFlag, n_periods: int) -> bool:
        """Lockstep for ``n_periods`` periods; False when the peer stopped answering or the
        plant failed (fail-safe, :meth:`_fail_safe`)."""
        try:
            return self._lockstep(stop, n_periods)
        except PlantStepError as exc:
            self._fail_safe(exc)
            return False

    def _lockstep(self, stop: StopFlag, n_periods: int) -> bool:
        delay: deque[float] = deque([0.0] * self.emu.scenario.transport_delay_samples)
        sent = self._send_sample(self.emu.measure())
        while self.periods < n_periods and not stop:
            cmd = None
            if sent:
                arrived, cmd = self._await_command(stop)
                if not arrived:
                    if not stop:
                        log.error(
                            "lockstep: no VALVE_CMD within %.1f s at k=%d; stopping",
                            self.opts.lockstep_timeout_s,
                            self.emu.k,
                        )
                    return bool(stop)
            delay.append(self._take_command(cmd))
            self.applied_a = self.emu.advance(delay.popleft())
            self._housekeeping()
            if self.periods < n_periods:
                sent = self._send_sample(self.emu.measure())
            self.io.idle()
        return True

    # ---- report -----------------------------------------------------------------------------
    def summary(self) -> dict[str, Any]:
        """Counters and period statistics (JSON-able)."""
        return {
            "periods": self.periods,
            "skipped_periods": self.skipped_periods,
            "frames_sent": dict(self.io.sent),
            "tx_errors": self.io.tx_errors,
            "frames_received": self.io.received,
            "received_by_verdict": {v.name: n for v, n in self.codec.counts.items()},
            "commands_accepted": self.hold.accepted,
            "command_timeouts": self.hold.timeouts,
            "lost_sensor_frames": self.lost_sensor,
            "lost_command_frames": self.lost_cmd,
            "command_conflicts": self.commanders.conflicts,
            "id_collisions": dict(self.io.collisions.by_name),
            "foreign_commands": self.commanders.foreign,
            "clipped_values": self.clipped,
            "inject_applied": self.inject_applied,
            "inject_rejected": self.inject_rejected,
            "inject_ignored": self.inject_ignored,
            "plant_failure": self.plant_failure,
            "stats": self.stats.summary(),
            "max_rss_bytes": peak_rss_bytes(),
        }
