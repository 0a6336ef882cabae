"""The emulated CiA 408 servo valve node: set-point in, spool actual and status word out.

RPDO 1 carries the control word (0x6040) and the spool set-point (0x6300.1), TPDO 1 the status
word (0x6041) and the spool actual value (0x6301.1), both ±16384 = ±100 % (the set-point of the
full-scale current, the actual value of the spool stroke). The cylinder position is served in
0x2100 (manufacturer-specific, 100 nm steps; TPDO 2 is free to map it, off by default). The plant gets
``set-point / 16384 × full_scale_current_a`` in ACTIVE and 0 A in every other state. Faults:
the master's heartbeat lost (0x1016) or the set-point RPDO late (0x1400.5 event timer) while
ACTIVE → FAULT_HOLD with EMCY 0x8130 / 0x8250, then the NMT state 0x1029.1 names; the node
leaving NMT OPERATIONAL (an NMT Stop or Enter Pre-operational, from whichever node) while enabled
(HOLD or ACTIVE) → FAULT_HOLD with 0x8100 (no PDO set-point reaches it any more; in STOPPED the
EMCY cannot be sent, the error register holds it); an injected device fault → FAULT with its code;
a persistent internal fault (the emulated plant stopped: :meth:`ValveNode.internal_fault`) →
FAULT with 0x6100, entered again whenever a reset (the R bit, an NMT reset) clears it.
"""

from __future__ import annotations

import logging
from typing import Any

from canopen.sdo import SdoAbortedError

from ehpss_hil.protocol.cia408.objects import (
    ABORT_RANGE,
    BIT_DEVIATION,
    BIT_LIMIT,
    CONTROL_MODE_SPOOL_CLOSED_LOOP,
    CONTROL_WORD,
    DEVICE_CONTROL_MODE,
    DEVICE_MODE,
    EMCY_COMMUNICATION,
    EMCY_HEARTBEAT,
    EMCY_INTERNAL_SOFTWARE,
    EMCY_NO_ERROR,
    EMCY_RPDO_TIMEOUT,
    ERR_REG_COMMUNICATION,
    ERR_REG_GENERIC,
    MONITORING_OFF,
    MONITORING_SYMMETRIC,
    MONITORING_WINDOW,
    SCALE_100_PERCENT,
    STATUS_WORD,
    VALVE_POSITION,
    VALVE_POSITION_STEP_NM,
    VPOC_ACTUAL,
    VPOC_DEMAND,
    VPOC_DEVIATION,
    VPOC_MONITORING_DELAY,
    VPOC_MONITORING_LOWER,
    VPOC_MONITORING_THRESHOLD,
    VPOC_MONITORING_TYPE,
    VPOC_MONITORING_UPPER,
    VPOC_SETPOINT,
    VPOC_SUB,
    DeviceState,
)

from .device import ValveStateMachine
from .node import CanopenSlave, Send
from .setpoint import SetpointPath
from .spoolloop import DeviationMonitor, SpoolLoop
from .store import Key

log = logging.getLogger("firmware_sim")
#: device states a persistent internal fault waits out (power-on: control words not obeyed yet)
_NOT_YET_RUNNING = (DeviceState.NOT_READY, DeviceState.INIT)
_INT16_MAX = 32767
_INT32_MAX = 2**31 - 1


class ValveNode(CanopenSlave):
    """A CiA 408 valve; ``full_scale_current_a`` (A) is the current of a +100 % set-point and
    ``stroke_m`` (m) the spool travel of a +100 % actual value."""

    def __init__(
        self,
        node_id: int,
        od: Any,
        send: Send,
        full_scale_current_a: float,
        stroke_m: float,
        overrides: dict[Key, int] | None = None,
    ) -> None:
        self.device = ValveStateMachine()
        self.full_scale_current_a = full_scale_current_a
        self._actual_per_m = SCALE_100_PERCENT / stroke_m
        self.spool_actual = 0
        self.position_value = 0
        self._spool_m = 0.0  # the spool measured last (m)
        self._stroke_m = stroke_m
        self.spool_loop = SpoolLoop(full_scale_current_a)
        self.monitor = DeviationMonitor()
        self._tick_s: float | None = None
        #: the EMCY code of a persistent internal fault (0: none)
        self.internal_fault_code = 0
        super().__init__(node_id, od, send, overrides)
        self.setpoint = SetpointPath(self.store)
        self.store.live[(STATUS_WORD, 0)] = self.status_word
        self.store.live[(VPOC_DEMAND, VPOC_SUB)] = lambda: round(self.setpoint.demand(self.device.state))
        self.store.live[(VPOC_DEVIATION, 0)] = self.deviation
        self.store.live[(VPOC_ACTUAL, VPOC_SUB)] = lambda: self.spool_actual
        self.store.live[(VALVE_POSITION, 0)] = lambda: self.position_value

    # ---- process values ---------------------------------------------------------------------
    @property
    def closed_loop(self) -> bool:
        """Device control mode 0x6043 = 2: the valve closes its own spool position loop."""
        return int(self.store.get(DEVICE_CONTROL_MODE, 0)) == CONTROL_MODE_SPOOL_CLOSED_LOOP

    def current_a(self) -> float:
        """The coil current the amplifier applies (A). Open loop: the demand value's share of
        full scale (the set-point in ACTIVE, the hold set-point in HOLD, after limits and ramp),
        else 0; closed loop: the spool loop's current for the demand as a spool position."""
        if self.closed_loop:
            return self.spool_loop.current_a
        return self.setpoint.demand(self.device.state) / SCALE_100_PERCENT * self.full_scale_current_a

    def deviation(self) -> int:
        """0x6350: demand − spool actual value (set-point units), clipped to INTEGER16."""
        d = round(self.setpoint.demand(self.device.state)) - self.spool_actual
        return max(-_INT16_MAX, min(_INT16_MAX, d))

    def status_word(self) -> int:
        """0x6041: the device state's bits, bit 10 while the limits clip the set-point, bit 11
        while the deviation monitoring alarms."""
        _, limited = self.setpoint.target(self.device.state)
        return (
            self.device.status_word
            | (BIT_LIMIT if limited else 0)
            | (BIT_DEVIATION if self.monitor.alarm else 0)
        )

    def measure(self, spool_m: float) -> None:
        """The spool position measured this period (m) → the actual value (0x6301.1)."""
        v = round(spool_m * self._actual_per_m)
        self.spool_actual = max(-_INT16_MAX, min(_INT16_MAX, v))
        self._spool_m = spool_m

    def measure_position(self, position_m: float) -> None:
        """The cylinder position measured this period (m) → 0x2100 (steps of
        ``VALVE_POSITION_STEP_NM``)."""
        v = round(position_m / (VALVE_POSITION_STEP_NM * 1e-9))
        self.position_value = max(-_INT32_MAX, min(_INT32_MAX, v))

    # ---- hooks ------------------------------------------------------------------------------
    def reset_application(self) -> None:
        self.device = ValveStateMachine()
        self.device.power_on(self._t_s)

    def tick(self, t_s: float) -> None:
        """The device's timed states (power-on, fault reaction), then the node's clocks."""
        was = self.device.state
        self.device.tick(t_s)
        if self.device.state != was:
            log.info("valve %d: %s -> %s", self.node_id, was.name, self.device.state.name)
        if self.internal_fault_code and self.device.state not in _NOT_YET_RUNNING:
            self._fault(self.internal_fault_code, ERR_REG_GENERIC, hold=False)  # a reset cleared it
        super().tick(t_s)
        state = self.device.state
        self.setpoint.tick(state, t_s)
        dt = 0.0 if self._tick_s is None else max(0.0, t_s - self._tick_s)
        self._tick_s = t_s
        demand = self.setpoint.demand(state)
        if self.closed_loop and state in (DeviceState.ACTIVE, DeviceState.HOLD):
            self.spool_loop.step(demand / SCALE_100_PERCENT * self._stroke_m, self._spool_m, dt)
        else:
            self.spool_loop.reset()
        delay_s = int(self.store.values.get((VPOC_MONITORING_DELAY, 0), 0)) * 1e-3
        self.monitor.update(self.monitoring_band(), self.deviation(), delay_s, t_s)

    def monitoring_band(self) -> tuple[int, int] | None:
        """The band (lower, upper) the deviation must stay in (set-point units) for the
        monitoring type 0x6351: ±0x6353, or [0x6355, 0x6354]; None when monitoring is off."""
        values = self.store.values
        kind = int(values.get((VPOC_MONITORING_TYPE, 0), MONITORING_OFF))
        if kind == MONITORING_SYMMETRIC:
            threshold = int(values.get((VPOC_MONITORING_THRESHOLD, 0), SCALE_100_PERCENT))
            return -threshold, threshold
        if kind == MONITORING_WINDOW:
            lower = int(values.get((VPOC_MONITORING_LOWER, 0), -SCALE_100_PERCENT))
            return lower, int(values.get((VPOC_MONITORING_UPPER, 0), SCALE_100_PERCENT))
        return None

    def _control_word(self, word: int) -> None:
        was = self.device.state
        if self.device.command(word):
            self.send_emcy(EMCY_NO_ERROR, 0)
        if self.device.state != was:
            log.info("valve %d: %s -> %s", self.node_id, was.name, self.device.state.name)

    def on_rpdo(self, values: list[tuple[Any, Any]]) -> None:
        for var, value in values:
            if (var.index, var.subindex) == (VPOC_SETPOINT, VPOC_SUB):
                value = max(-SCALE_100_PERCENT, min(SCALE_100_PERCENT, int(value)))
            self.store.set(var.index, var.subindex, value)
            if var.index == CONTROL_WORD:
                self._control_word(int(value))

    def on_object_write(self, index: int, sub: int, value: Any) -> None:
        if index == CONTROL_WORD:
            self._control_word(int(value))
        elif index in (DEVICE_MODE, DEVICE_CONTROL_MODE) and self.device.state == DeviceState.ACTIVE:
            raise SdoAbortedError(ABORT_RANGE)

    def on_heartbeat_lost(self, producer: int) -> None:
        self._fault(EMCY_HEARTBEAT, ERR_REG_GENERIC | ERR_REG_COMMUNICATION, hold=True)
        self.communication_error()

    def on_rpdo_timeout(self, comm_index: int) -> None:
        if self.device.state == DeviceState.ACTIVE:
            self._fault(EMCY_RPDO_TIMEOUT, ERR_REG_GENERIC | ERR_REG_COMMUNICATION, hold=True)
            self.communication_error()

    def on_left_operational(self) -> None:
        if self.device.state in (DeviceState.HOLD, DeviceState.ACTIVE):
            self._fault(EMCY_COMMUNICATION, ERR_REG_GENERIC | ERR_REG_COMMUNICATION, hold=True)

    def inject_fault(self, code: int) -> None:
        """A device fault with EMCY ``code`` (a scenario's ``device_fault`` event) → FAULT."""
        self._fault(code, ERR_REG_GENERIC, hold=False)

    def internal_fault(self, code: int = EMCY_INTERNAL_SOFTWARE) -> None:
        """A persistent internal fault with EMCY ``code`` (the emulated plant stopped): FAULT now
        (0 A after the fault reaction) and again at each tick a reset left it out of a fault
        state. The EMCY goes out even when another fault latched first: a new error (CiA 301)."""
        self.internal_fault_code = code
        if not self._fault(code, ERR_REG_GENERIC, hold=False):
            self.send_emcy(code, ERR_REG_GENERIC)

    def _fault(self, code: int, register: int, hold: bool) -> bool:
        """Enter the fault reaction with EMCY ``code``; False when a fault was latched already."""
        was = self.device.state
        if not self.device.fault(code, hold):
            return False
        log.warning("valve %d: %s -> %s (EMCY 0x%04X)", self.node_id, was.name, self.device.state.name, code)
        self.send_emcy(code, register)
        return True
