"""Controller lifecycle (docs/design.md §8), numbered as the DBC's CTRL_STATUS ``State`` VAL_.

INIT → CONFIGURED → ACTIVE ⇄ FAULT → STOPPED (STOPPED reachable from any state).
"""

from __future__ import annotations

from enum import IntEnum

from ..errors import EhpssError
from ..protocol.failsafe import FailsafeReason


class State(IntEnum):
    """CTRL_STATUS State."""

    INIT = 0
    CONFIGURED = 1
    ACTIVE = 2
    FAULT = 3
    STOPPED = 4


#: CiA 301 heartbeat NMT state for each lifecycle state
NMT_STATE = {State.INIT: 0, State.CONFIGURED: 127, State.ACTIVE: 5, State.FAULT: 127, State.STOPPED: 4}

_ALLOWED = {
    State.INIT: {State.CONFIGURED, State.STOPPED},
    State.CONFIGURED: {State.ACTIVE, State.STOPPED},
    State.ACTIVE: {State.FAULT, State.STOPPED},
    State.FAULT: {State.ACTIVE, State.STOPPED},
    State.STOPPED: set(),
}


class LifecycleError(EhpssError, RuntimeError):
    """A transition the lifecycle does not allow."""


class Lifecycle:
    """Current state + fail-safe reason, with checked transitions and a transition count."""

    def __init__(self) -> None:
        self.state = State.INIT
        self.reason = FailsafeReason.NONE
        self.transitions = 0

    def to(self, new: State, reason: FailsafeReason = FailsafeReason.NONE) -> None:
        """Move to ``new`` (FAULT carries ``reason``); raises LifecycleError if not allowed."""
        if new is self.state:
            return
        if new not in _ALLOWED[self.state]:
            raise LifecycleError(f"lifecycle: {self.state.name} -> {new.name} is not allowed")
        self.state = new
        self.reason = (
            reason if new is State.FAULT else (self.reason if new is State.STOPPED else FailsafeReason.NONE)
        )
        self.transitions += 1

    @property
    def nmt_state(self) -> int:
        """The heartbeat's NmtState for the current state."""
        return NMT_STATE[self.state]
