"""The emulated CiA 406 linear encoder node: the piston position as its position value."""

from __future__ import annotations

from typing import Any

from ehpss_hil.protocol.cia408.objects import MEASURING_STEP, POSITION_VALUE

from .node import CanopenSlave, Send
from .store import Key

_INT32_MAX = 2**31 - 1
_NM = 1e-9


class EncoderNode(CanopenSlave):
    """A CiA 406 absolute linear encoder; the position value (0x6004, TPDO 1) counts measuring
    steps of 0x6005.1 nm."""

    def __init__(self, node_id: int, od: Any, send: Send, overrides: dict[Key, int] | None = None) -> None:
        self.position_value = 0
        super().__init__(node_id, od, send, overrides)
        self.store.live[(POSITION_VALUE, 0)] = lambda: self.position_value

    @property
    def step_m(self) -> float:
        """The measuring step (m)."""
        return int(self.store.get(MEASURING_STEP, 1)) * _NM

    def measure(self, position_m: float) -> None:
        """The position sensor's reading this period (m) → the position value (steps)."""
        v = round(position_m / self.step_m)
        self.position_value = max(-_INT32_MAX, min(_INT32_MAX, v))
