"""The controller daemon's cycle (docs/design.md §8): read → E2E → watchdog → step → one VALVE_CMD.

Per cycle: drain every pending frame without blocking (own echoes dropped by :class:`FrameIO`);
the newest usable SENSOR_POS/SENSOR_AUX values are used; the watchdog counts the cycle; in
ACTIVE the controller steps once, in FAULT the fail-safe command is sent (0 A with Enable 0, or
the last command with ``failsafe: hold``); exactly one VALVE_CMD goes out, echoing the counter of
the SENSOR_POS frame used and the cycle count. CTRL_STATUS + CTRL_INDEX at ``status_rate_hz``,
CTRL_STATS at 10 Hz, heartbeat at ``heartbeat_rate_hz``.

Lifecycle: CONFIGURED (0 A, Enable 0, watchdog idle) until the first usable sensor frame, then
ACTIVE; the reference starts at that cycle. Realtime: a fixed deadline grid; periods skipped by
an overrun count for the watchdog as cycles without data and are stepped without data before the
next cycle (:meth:`ControllerLoop.catch_up`), so the controller's clock stays on the grid; more
than the predictors bridge (``RESYNC_SAMPLES``) is a fault (LOOP_OVERRUN), never stepped. A sensor
frame received longer ago than the watchdog window is stale: counted, never used; a cycle that
stalls after its drain for longer than that window sends the fail-safe command (LOOP_OVERRUN), not
the command computed on what it read. Lockstep: one cycle
per received sensor pair (triggered by SENSOR_AUX, which the emulator sends after SENSOR_POS).
"""

from __future__ import annotations

import time
from typing import TYPE_CHECKING

import can

from ..codec import Verdict
from ..control.base import Controller, Measurement
from ..control.sampleclock import RESYNC_SAMPLES
from ..driver import ControllerDriver
from ..protocol.failsafe import FailsafeReason
from ..scenario import Reference, ReferenceBlocks
from .bushealth import BusHealth
from .foreign import CollisionGuard, SetpointGate
from .frameio import FrameIO
from .lifecycle import Lifecycle, State
from .loop_options import CIA408_OWN_FRAMES, OWN_FRAMES, LoopOptions
from .periodic import PeriodicFrames
from .stats import LoopStats
from .status_frames import StatusReporter
from .transitions import Transitions
from .watchdog import SensorWatchdog

if TYPE_CHECKING:
    from ..protocol.cia408.master import CyclicMaster

__all__ = ["CIA408_OWN_FRAMES", "OWN_FRAMES", "ControllerLoop", "LoopOptions"]

_E2E_VERDICTS = (Verdict.CRC_ERROR, Verdict.REPEATED, Verdict.WRONG_SEQUENCE, Verdict.BAD_DLC)
_SEQUENCE_VERDICTS = (Verdict.REPEATED, Verdict.WRONG_SEQUENCE)


class ControllerLoop:
    """One controller instance on one bus; ``master``: the CANopen master's part of each cycle
    (``protocol: cia408``: it goes ACTIVE only with the valve ACTIVE, its faults are fail-safe
    reasons, a SYNC follows each command)."""

    def __init__(
        self,
        controller: Controller,
        io: FrameIO,
        reference: Reference,
        opts: LoopOptions,
        master: CyclicMaster | None = None,
    ) -> None:
        self.controller = controller
        self.master = master
        self.io = io
        self.codec = io.codec
        self.opts = opts
        self.ts_s = 1.0 / opts.rate_hz
        self.ref = ReferenceBlocks(reference, self.ts_s)
        #: sensor values → Measurement → step → command (the same driver as replay and the sim)
        self.driver = ControllerDriver(controller, self.ref.at, opts.current_limit_a)
        self.wd = SensorWatchdog(opts.watchdog, max_skipped=RESYNC_SAMPLES)
        #: a sensor frame received longer ago than this (s) is stale: the watchdog's window
        self.stale_after_s = opts.watchdog.timeout_cycles * self.ts_s
        #: frames are aged (realtime, and only where a frame's timestamp is its receive time;
        #: on ``virtual`` it is the in-process sender's send time)
        self.check_age = io.receive_timestamps
        #: sensor frames dropped as stale
        self.stale_frames = 0
        self._stale_in_cycle = 0
        self._rx_now = 0.0  # wall-clock time (s) the frames being drained are aged against
        self._late = False  # this cycle started after its deadline
        self._backlog = False  # the frames being drained follow skipped periods
        self.life = Lifecycle()
        self.life.to(State.CONFIGURED)
        #: a second transmitter (ID_COLLISION) and the SETPOINT policy (runtime/foreign.py)
        self.guard = CollisionGuard(opts.watchdog, io.collisions)
        #: send failures and error frames under the watchdog's policy (BUS_ERROR)
        io.health = BusHealth(opts.watchdog)
        self.setpoints = SetpointGate(opts.setpoint)
        self.stats = LoopStats(opts.stats_capacity)
        #: CONFIGURED → ACTIVE ⇄ FAULT, decided each cycle
        self.transitions = Transitions(
            self.life, self.wd, self.guard, io.health, self.driver, master, opts.watchdog.failsafe
        )
        #: the sensor pair's CAN IDs under this loop's protocol profile
        self.id_pos = self.codec.can_id("SENSOR_POS")
        self.id_aux = self.codec.can_id("SENSOR_AUX")
        self._id_setpoint = self.codec.can_id("SETPOINT")
        #: CTRL_STATUS/CTRL_INDEX/CTRL_STATS/heartbeat after each cycle, the log's counter line
        self.periodic = PeriodicFrames(opts)
        self.cycles = 0
        self.failsafe_cycles = 0
        #: grid periods skipped by overruns, stepped without a frame (:meth:`catch_up`)
        self.skipped_periods = 0
        #: cycles started before their deadline by the sensor pair's arrival (wake_on_sensor)
        self.woken_by_sensor = 0
        self._woke_wall_s = 0.0
        self._aux_ts = 0.0
        self.overruns = 0
        self.last_current_a = 0.0
        self.last_enable = False
        self.reporter = StatusReporter(io)
        self._rx_ids = frozenset((self.id_pos, self.id_aux, self._id_setpoint))
        #: one cycle per received sensor pair (set by :func:`.loop_run.run_lockstep`, which drives
        #: this loop as :func:`.loop_run.run_realtime` does on the deadline grid)
        self.lockstep = False
        self._last_pos_counter = 0  # counter of the newest usable SENSOR_POS (lockstep gaps)
        self._reset_cycle_rx()

    # ---- receive ----------------------------------------------------------------------------
    def _reset_cycle_rx(self) -> None:
        self._fresh = False
        self._late = False
        self._stale_in_cycle = 0
        self._aux_fresh = False
        self._e2e_bad = 0
        self._implausible = 0
        self._pos_counter = 0
        self._pos_ts = 0.0

    def _current_frame(self, msg: can.Message) -> bool:
        """False for a frame that belongs to an earlier period: received before the stale
        window (where frames are aged), or drained right after skipped periods (a backlog)."""
        if self.lockstep:
            return True
        if self.check_age:
            return self._rx_now - msg.timestamp <= self.stale_after_s
        return not self._backlog

    def on_frame(self, msg: can.Message) -> Verdict | None:
        """Consume one received frame (IDs other than sensors/SETPOINT are only logged); returns
        its verdict (None for IDs not consumed).

        Realtime, on buses that stamp the receive time (:attr:`check_age`: udp_multicast and
        socketcan, the kernel's ``SO_TIMESTAMPNS`` on the host's wall clock): a usable sensor
        frame received more than :attr:`stale_after_s` before this drain is stale: classified
        (its E2E counter moves the sequence on), counted, not used.

        Lockstep only: a SENSOR_POS whose counter shows lost sensor samples (OK_SOME_LOST) first
        steps those samples without data (:meth:`catch_up`), as the emulator advanced over them,
        so the reference stays on the plant's sample clock."""
        fid = msg.arbitration_id
        if fid not in self._rx_ids:
            if self.master is not None:
                self.master.on_frame(msg)
            return None
        d = self.codec.classify(msg)
        if fid == self.id_pos:
            self.guard.sensor.add(
                d.verdict in _SEQUENCE_VERDICTS, bytes(msg.data), self.cycles, self._current_frame(msg)
            )
        if not d.verdict.usable or d.values is None:
            if fid != self._id_setpoint:
                if d.verdict is Verdict.OUT_OF_RANGE:
                    self._implausible += 1
                elif d.verdict in _E2E_VERDICTS:
                    self._e2e_bad += 1
            return d.verdict
        v = d.values
        if (
            self.check_age
            and fid != self._id_setpoint
            and not self.lockstep
            and self._rx_now - msg.timestamp > self.stale_after_s
        ):
            self.stale_frames += 1
            self._stale_in_cycle += 1
            return d.verdict
        if fid == self.id_pos:
            counter = d.counter or 0
            if self.lockstep and d.verdict is Verdict.OK_SOME_LOST:
                self.catch_up((counter - self._last_pos_counter - 1) & 0x0F, overrun=False)
            self._last_pos_counter = counter
            self._fresh = True
            self._pos_counter = counter
            self._pos_ts = msg.timestamp
        elif fid == self.id_aux:
            self._aux_fresh = True
            self._aux_ts = msg.timestamp
            self.guard.command_conflict(bool(v.get("CommandConflict", 0)))
        self.driver.take(d, self.setpoints.admit)
        return d.verdict

    # ---- the driver's state, as the loop's --------------------------------------------------
    @property
    def meas(self) -> Measurement:
        """The measurement the controller steps on (the driver's)."""
        return self.driver.meas

    @property
    def k_active(self) -> int:
        """The reference sample of the next cycle (cycles run, caught up or in fail-safe)."""
        return self.driver.k

    @property
    def saturations(self) -> int:
        """Commands clipped to ±current_limit_a or non-finite."""
        return self.driver.saturations

    # ---- one cycle --------------------------------------------------------------------------
    def _update_state(self) -> None:
        """This cycle's lifecycle transition (:class:`~.transitions.Transitions`)."""
        self.transitions.update(
            self.cycles,
            self.controller.mode,
            self._fresh,
            self._e2e_bad,
            self._implausible,
            self._late,
            self._stale_in_cycle,
            self.stale_after_s,
        )

    def enter_fault(self, reason: FailsafeReason | None = None) -> None:
        """ACTIVE → FAULT for ``reason`` (None: the watchdog's)."""
        self.transitions.enter_fault(self.cycles, reason)

    def _command(self) -> tuple[float, bool]:
        st = self.life.state
        if st is State.ACTIVE:
            command = self.driver.step()
            if not self._stalled_since_drain():
                return command
            self.wd.stall()
            self.enter_fault()
        if self.life.state is State.FAULT:
            self.failsafe_cycles += 1
            self.driver.failsafe_cycle()
            if self.opts.watchdog.failsafe == "hold":
                return self.last_current_a, self.last_enable
            return 0.0, False
        self.driver.idle_cycle()
        return 0.0, False

    def _stalled_since_drain(self) -> bool:
        """Realtime, on buses that stamp the receive time: the cycle stalled after its drain (the
        process was stopped or starved mid-cycle) for longer than the watchdog window, so the
        command just computed rests on data that is stale by the time it would be sent. It is
        not sent: the watchdog trips LOOP_OVERRUN and the fail-safe command goes out instead.
        (A process frozen inside the send itself still sends afterwards: no check can see that.)"""
        return self.check_age and not self.lockstep and time.time() - self._rx_now > self.stale_after_s

    def catch_up(self, periods: int, overrun: bool = True) -> None:
        """Grid periods the loop slept through (``overrun``: the deadline timer skipped them;
        else lockstep's lost sensor samples): the controller's clock stays on the grid. Each one
        is a cycle without a sensor frame (``fresh`` False: the predictors advance, the PI
        integrates, the reference moves on) and without a frame sent (``command_sent`` False:
        the valve holds the previous command); ``cycles`` and so VALVE_CMD's CycleCount count
        them, so the reference index and CycleCount keep matching the emulator's sample clock.

        Overrun periods count for the watchdog as cycles without data
        (:meth:`~.watchdog.SensorWatchdog.skip`): more than ``RESYNC_SAMPLES`` at once,
        ``timeout_cycles`` at once, or starvation is LOOP_OVERRUN, and then the law is not stepped
        at all (leaving FAULT resets it). So the law steps here at most ``RESYNC_SAMPLES`` times:
        lockstep's gaps come from the 4-bit E2E counter."""
        if periods <= 0:
            return
        self.skipped_periods += periods
        self.cycles += periods
        st = self.life.state
        if overrun and st in (State.ACTIVE, State.FAULT):
            tripped = self.wd.skip(periods)
            if tripped and st is State.ACTIVE:
                self.enter_fault()
        if self.life.state is State.FAULT:
            self.driver.k += periods
            self.failsafe_cycles += periods
            return
        if self.life.state is not State.ACTIVE:
            return
        self.driver.catch_up(periods)

    def poll_cycle(self, skipped: int = 0, drain: bool = True, late: bool = False) -> float | None:
        """One realtime cycle without waiting: the ``skipped`` grid periods before it
        (:meth:`catch_up`), drain every pending frame (unless ``drain`` is False: the caller
        has just drained the bus), then :meth:`cycle`. ``late``: the cycle started after its
        deadline (the watchdog's starvation window).

        Returns the receive timestamp (wall-clock s) of the SENSOR_POS frame used, or None."""
        self.catch_up(skipped)
        self._backlog = skipped > 0
        if drain:
            self.drain()
        used = self._pos_ts if self._fresh else None
        self._late = late
        self.cycle()
        return used

    def cycle(self) -> None:
        """Everything after the drain: state, control step, VALVE_CMD, periodic frames."""
        self._update_state()
        current, enable = self._command()
        self.send_command(current, enable)
        if self.master is not None:
            for name, msg in self.master.take_frames():
                self.io.send_message(name, msg)
            if self.master.produces_sync:
                self.io.send("SYNC", {"Cycle": self.cycles})
        if self._fresh:
            self.stats.latency.add(time.time() - self._pos_ts)
        self._reset_cycle_rx()
        self.cycles += 1
        self.periodic.after_cycle(self)
        self.io.idle()

    def send_command(self, current_a: float, enable: bool) -> None:
        """One VALVE_CMD (A) with the sensor counter echo and the cycle count."""
        self.io.send(
            "VALVE_CMD",
            {
                "CurrentSetpoint": current_a,
                "Enable": int(enable),
                "SensorCounterEcho": self._pos_counter,
                "CycleCount": self.cycles & 0xFFFF,
            },
        )
        self.last_current_a = current_a
        self.last_enable = enable

    # ---- status frames ----------------------------------------------------------------------
    def send_status(self, all_index: bool = False) -> None:
        """CTRL_STATUS now (with CTRL_DEVICE under the CANopen master), its CTRL_INDEX frames one
        per following cycle (or all at once)."""
        self.reporter.send(self.controller, self.life, all_index)
        if self.master is not None:
            self.io.send("CTRL_DEVICE", self.master.device_values())

    # ---- drivers ----------------------------------------------------------------------------
    def start(self) -> None:
        """Announce boot-up (CiA 301 heartbeat state 0)."""
        self.io.send("HEARTBEAT_CTRL", {"NmtState": 0})

    @property
    def wake_lateness_s(self) -> float:
        """A cycle woken by its sensor pair: how long after the pair's SENSOR_AUX (s) it woke."""
        return max(0.0, self._woke_wall_s - self._aux_ts)

    def drain(self, limit: int = 1000) -> int:
        """Consume the frames pending now (at most ``limit``), aged against this moment
        (:meth:`on_frame`); returns how many were read."""
        self._rx_now = time.time()
        n = 0
        for msg in self.io.drain(limit):
            self.on_frame(msg)
            n += 1
        return n

    def drain_for_wake(self) -> bool:
        """The bus became readable before the deadline: consume what arrived (this cycle's
        drain, done early); True once the cycle has a usable sensor pair."""
        self.drain()
        self._woke_wall_s = self._rx_now
        return self._fresh and self._aux_fresh

    def shutdown(self) -> None:
        """Zero current with Enable 0, state STOPPED, final status and heartbeat."""
        for _ in self.io.drain():  # log what arrived since the last cycle
            pass
        if self.master is not None:
            self.master.stop()  # control word DISABLED with the set-point 0
        self.send_command(0.0, False)
        self.life.to(State.STOPPED)
        self.send_status(all_index=True)
        self.io.send("HEARTBEAT_CTRL", {"NmtState": self.life.nmt_state})
