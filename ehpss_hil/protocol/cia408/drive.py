"""The master's side of the CiA 408 device state machine: the control word each cycle, from the
status word the valve last reported (pure: no bus, no clock).

Enabling walks DISABLED → HOLD → ACTIVE, one step per confirmation: each request (D, then D+H,
then D+H+M) stays in the control word until the status word shows the state it asks for. A
latched fault (FAULT, FAULT_HOLD) met while enabling is reset by a rising edge of bit R: one
cycle with R set, then R clear while the status word catches up, after which enabling starts
over from DISABLED. At most :data:`MAX_FAULT_RESETS` resets are tried.

Once the valve has been ACTIVE, every status word is checked: one that shows any other state is
a device fault (:attr:`DeviceDrive.left_active`), never reset by the drive itself; the control
word then asks for DISABLED, as it does after :meth:`DeviceDrive.disable` (the stop sequence).
"""

from __future__ import annotations

from .objects import BIT_D, BIT_H, BIT_M, BIT_R, DeviceState, state_of_status

#: fault resets the drive tries while enabling before it gives up (a fault that comes back)
MAX_FAULT_RESETS = 3
#: cycles with R clear after a reset edge before the next one (the status word's round trip)
RESET_WAIT_CYCLES = 20

#: the control word requesting each state (CiA 408 bits D, H, M)
REQUEST = {
    DeviceState.DISABLED: BIT_D,
    DeviceState.HOLD: BIT_D | BIT_H,
    DeviceState.ACTIVE: BIT_D | BIT_H | BIT_M,
}
_NEXT = {DeviceState.DISABLED: DeviceState.HOLD, DeviceState.HOLD: DeviceState.ACTIVE}
_FAULTS = (DeviceState.FAULT, DeviceState.FAULT_HOLD)


class DeviceDrive:
    """The control word of one CiA 408 valve, cycle by cycle."""

    def __init__(self) -> None:
        self.request = DeviceState.DISABLED
        self.control_word = REQUEST[DeviceState.DISABLED]
        #: the state the last status word showed
        self.state = DeviceState.NOT_READY
        #: the valve has been ACTIVE since the drive was made
        self.was_active = False
        #: the status word left ACTIVE after it had been ACTIVE (the state it showed then)
        self.left_active: DeviceState | None = None
        self.fault_resets = 0
        self._reset_wait = 0
        self._disabled = False

    @property
    def active(self) -> bool:
        """The valve shows ACTIVE and the drive asks for it: the set-point drives the spool."""
        return self.state is DeviceState.ACTIVE and self.request is DeviceState.ACTIVE

    @property
    def gave_up(self) -> bool:
        """The fault came back after :data:`MAX_FAULT_RESETS` resets."""
        return self.fault_resets >= MAX_FAULT_RESETS and self.state in _FAULTS

    def disable(self) -> None:
        """From now on ask for DISABLED (fail-safe, stop)."""
        self._disabled = True
        self.request = DeviceState.DISABLED
        self.control_word = REQUEST[DeviceState.DISABLED]

    def update(self, status_word: int) -> int:
        """The newest status word (0x6041) → the control word (0x6040) to send this cycle."""
        self.state = state = state_of_status(status_word)
        if self.was_active and state is not DeviceState.ACTIVE and self.left_active is None:
            self.left_active = state
            self.disable()
        if state is DeviceState.ACTIVE and self.request is DeviceState.ACTIVE:
            self.was_active = True
        if self._disabled:
            return self.control_word
        if state in _FAULTS:
            return self._reset_fault()
        self._reset_wait = 0
        if state is self.request and state in _NEXT:
            self.request = _NEXT[state]
        self.control_word = REQUEST[self.request]
        return self.control_word

    def _reset_fault(self) -> int:
        """One cycle with R set (the rising edge), then R clear for :data:`RESET_WAIT_CYCLES`
        while the status word catches up, then the next edge."""
        self.request = DeviceState.DISABLED
        self.control_word = REQUEST[DeviceState.DISABLED]
        if self._reset_wait > 0:
            self._reset_wait -= 1
        elif self.fault_resets < MAX_FAULT_RESETS:
            self._reset_wait = RESET_WAIT_CYCLES
            self.fault_resets += 1
            self.control_word |= BIT_R
        return self.control_word
