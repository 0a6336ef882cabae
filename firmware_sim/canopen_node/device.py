"""The CiA 408 device state machine of the emulated valve (pure: no bus; loop time passed in).

Power-on: NOT_READY for :data:`NOT_READY_S`, then INIT for :data:`INIT_S`, then DISABLED (each
step at the first :meth:`ValveStateMachine.tick` after its time); control words are stored but
not obeyed before DISABLED, where the last one (its D/H/M request) takes effect at once. Then
DISABLED → HOLD → ACTIVE as the control word's D/H/M bits request (any of them directly; the
valve is driven only in ACTIVE). A fault goes through FAULT_REACTION (0 A, for
:data:`FAULT_REACTION_S`) and latches FAULT (an injected device fault) or FAULT_HOLD (master
heartbeat lost, set-point RPDO timed out, NMT OPERATIONAL left while enabled) until a rising
edge of the control word's R bit, which returns to DISABLED. Bits:
:mod:`ehpss_hil.protocol.cia408.objects`.
"""

from __future__ import annotations

from ehpss_hil.protocol.cia408.objects import BIT_D, BIT_H, BIT_M, BIT_R, STATUS_OF, DeviceState

_FAULTS = (DeviceState.FAULT, DeviceState.FAULT_HOLD, DeviceState.FAULT_REACTION)
_TIMED = (DeviceState.NOT_READY, DeviceState.INIT, DeviceState.FAULT_REACTION)
#: how long the emulated valve stays NOT_READY and then INIT after power-on (s)
NOT_READY_S = 0.005
INIT_S = 0.005
#: how long its fault reaction lasts before the fault state latches (s)
FAULT_REACTION_S = 0.002
#: loop times are k·Ts: compare with this slack (s)
_EPS_S = 1e-9


class ValveStateMachine:
    """State, the last control word, and the fault that latched (an EMCY code, 0 = none)."""

    def __init__(self) -> None:
        self.state = DeviceState.NOT_READY
        self.control_word = 0
        self.fault_code = 0
        self.transitions = 0
        self._t_s = 0.0
        self._until_s = 0.0  # when the present timed state (NOT_READY, INIT, FAULT_REACTION) ends
        self._after = DeviceState.DISABLED  # … and the state that follows it

    def power_on(self, t_s: float = 0.0) -> None:
        """Power-on at loop time ``t_s`` (s): NOT_READY, control word cleared, no fault."""
        self.control_word = 0
        self.fault_code = 0
        self._t_s = t_s
        self._go(DeviceState.NOT_READY)
        self._until_s, self._after = t_s + NOT_READY_S, DeviceState.INIT

    def tick(self, t_s: float) -> None:
        """Loop time ``t_s`` (s): each timed state whose time is up gives way to the next."""
        self._t_s = t_s
        while self.state in _TIMED and t_s >= self._until_s - _EPS_S:
            nxt = self._after
            self._go(nxt)
            if nxt is DeviceState.INIT:
                self._until_s, self._after = self._until_s + INIT_S, DeviceState.DISABLED
            elif nxt is DeviceState.DISABLED:
                self._request(self.control_word)

    def _go(self, state: DeviceState) -> None:
        if state != self.state:
            self.transitions += 1
            self.state = state

    @property
    def faulted(self) -> bool:
        """A fault is latched or its reaction runs (FAULT, FAULT_HOLD, FAULT_REACTION)."""
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
            if rising_r and self.state is not DeviceState.FAULT_REACTION:
                self.fault_code = 0
                self._go(DeviceState.DISABLED)
                return True
            return False
        if self.state in (DeviceState.NOT_READY, DeviceState.INIT):
            return False
        self._request(word)
        return False

    def _request(self, word: int) -> None:
        if word & (BIT_D | BIT_H | BIT_M) == BIT_D | BIT_H | BIT_M:
            self._go(DeviceState.ACTIVE)
        elif word & (BIT_D | BIT_H) == BIT_D | BIT_H:
            self._go(DeviceState.HOLD)
        else:
            self._go(DeviceState.DISABLED)

    def fault(self, code: int, hold: bool) -> bool:
        """A fault with EMCY ``code``: FAULT_REACTION, then FAULT_HOLD when ``hold`` else FAULT;
        returns False when a fault was latched already (the first one stays)."""
        if self.faulted:
            return False
        self.fault_code = code
        self._go(DeviceState.FAULT_REACTION)
        self._until_s = self._t_s + FAULT_REACTION_S
        self._after = DeviceState.FAULT_HOLD if hold else DeviceState.FAULT
        return True
