"""The emulated CiA 406 linear encoder node: the piston position as its position value.

Besides the position value (0x6004) and its step (0x6005.1): the preset (0x6003; writing it
sets the offset 0x6509 so that the position value equals the preset at that moment), the speed
value (0x6030.1, the position's change over the last period in 0.1 mm/s), the operating status
(0x6500, the operating parameters 0x6000 as set) and the constant identification objects of the
EDS (0x6002, 0x6501–0x6508, 0x650A, 0x650B)."""

from __future__ import annotations

from typing import Any

from ehpss_hil.protocol.cia408.objects import (
    MEASURING_STEP,
    OFFSET_VALUE,
    OPERATING_PARAMETERS,
    OPERATING_STATUS,
    POSITION_VALUE,
    PRESET_VALUE,
    SPEED_LSB_M_S,
    SPEED_VALUE,
)

from .node import CanopenSlave, Send
from .store import Key

_INT32_MAX = 2**31 - 1
_INT16_MAX = 2**15 - 1
_NM = 1e-9


class EncoderNode(CanopenSlave):
    """A CiA 406 absolute linear encoder; the position value (0x6004, TPDO 1) counts measuring
    steps of 0x6005.1 nm."""

    def __init__(self, node_id: int, od: Any, send: Send, overrides: dict[Key, int] | None = None) -> None:
        self.position_value = 0
        self.speed_value = 0
        self._raw = 0  # the position in steps before the preset's offset
        self._last: tuple[float, float] | None = None  # (loop time s, position m) measured last
        super().__init__(node_id, od, send, overrides)
        self.store.live[(POSITION_VALUE, 0)] = lambda: self.position_value
        self.store.live[(SPEED_VALUE, 1)] = lambda: self.speed_value
        if OPERATING_STATUS in od:
            self.store.live[(OPERATING_STATUS, 0)] = lambda: self.store.get(OPERATING_PARAMETERS, 0)

    @property
    def step_m(self) -> float:
        """The measuring step (m)."""
        return int(self.store.get(MEASURING_STEP, 1)) * _NM

    def measure(self, position_m: float) -> None:
        """The position sensor's reading this period (m) → the position value (steps)."""
        self._raw = round(position_m / self.step_m)
        self.position_value = self._clip32(self._raw + self._offset())
        if self._last is not None and self._t_s > self._last[0]:
            v = (position_m - self._last[1]) / (self._t_s - self._last[0]) / SPEED_LSB_M_S
            self.speed_value = max(-_INT16_MAX, min(_INT16_MAX, round(v)))
        self._last = (self._t_s, position_m)

    @staticmethod
    def _clip32(v: int) -> int:
        return max(-_INT32_MAX, min(_INT32_MAX, v))

    def _offset(self) -> int:
        return int(self.store.values.get((OFFSET_VALUE, 0), 0))

    def on_object_write(self, index: int, sub: int, value: Any) -> None:
        if index == PRESET_VALUE and (OFFSET_VALUE, 0) in self.store.values:
            self.store.set(OFFSET_VALUE, 0, self._clip32(int(value) - self._raw))
            self.position_value = self._clip32(self._raw + self._offset())
