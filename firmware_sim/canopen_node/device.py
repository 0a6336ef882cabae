"""The CiA 408 device state machine of the emulated valve (pure: no bus, no clock).

DISABLED → HOLD → ACTIVE as the control word's D/H/M bits request (any of them directly; the
valve is driven only in ACTIVE); a fault latches FAULT (from an injected device fault) or
FAULT_HOLD (master heartbeat lost, set-point RPDO timed out) until a rising edge of the
control word's R bit, which returns to DISABLED. Bits: :mod:`ehpss_hil.protocol.cia408.objects`.
"""

from __future__ import annotations

from ehpss_hil.protocol.cia408.objects import BIT_D, BIT_H, BIT_M, BIT_R, STATUS_OF, DeviceState

_FAULTS = (DeviceState.FAULT, DeviceState.FAULT_HOLD)


class ValveStateMachine:
    """State, the last control word, and the fault that latched (an EMCY code, 0 = none)."""

    def __init__(self) -> None:
        self.state = DeviceState.NOT_READY
        self.control_word = 0
        self.fault_code = 0
        self.transitions = 0

    def power_on(self) -> None:
        """Initialisation done: NOT_READY → DISABLED (control word cleared, no fault)."""
        self.control_word = 0
        self.fault_code = 0
        self._go(DeviceState.DISABLED)

    def _go(self, state: DeviceState) -> None:
        if state != self.state:
            self.transitions += 1
            self.state = state

    @property
    def faulted(self) -> bool:
        """A fault is latched (FAULT or FAULT_HOLD)."""
        return self.state in _FAULTS

    @property
    def status_word(self) -> int:
        """The status word (0x6041) of the present state."""
        return STATUS_OF[self.state]

    def command(self, word: int) -> bool:
        """A control word (0x6040) arrived; returns True when it reset a latched fault."""
        rising_r = bool(word & BIT_R) and not self.control_word & BIT_R
        self.control_word = word
        if self.faulted:
            if rising_r:
                self.fault_code = 0
                self._go(DeviceState.DISABLED)
                return True
            return False
        if self.state == DeviceState.NOT_READY:
            return False
        if word & (BIT_D | BIT_H | BIT_M) == BIT_D | BIT_H | BIT_M:
            self._go(DeviceState.ACTIVE)
        elif word & (BIT_D | BIT_H) == BIT_D | BIT_H:
            self._go(DeviceState.HOLD)
        else:
            self._go(DeviceState.DISABLED)
        return False

    def fault(self, code: int, hold: bool) -> bool:
        """A fault with EMCY ``code``: FAULT_HOLD when ``hold`` else FAULT; returns False when a
        fault was latched already (the first one stays)."""
        if self.faulted:
            return False
        self.fault_code = code
        self._go(DeviceState.FAULT_HOLD if hold else DeviceState.FAULT)
        return True
