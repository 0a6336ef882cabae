"""The emulated CiA 408 valve's set-point path (pure: no bus; loop time passed in).

The target is the spool set-point 0x6300.1 in ACTIVE, the hold set-point 0x6314.1 in HOLD and
0 in every other state; it is clipped to the lower and upper limits 0x6321.1 / 0x6320.1 (the
status word's bit 10 while it is), then, with ramp type 0x6330 = 1 and a ramp time 0x6331.1 > 0
(ms for 100 %), the demand value 0x6311.1 follows it at that rate; with ramp type 0 the demand is
the limited target itself. Outside ACTIVE and HOLD the demand is 0 at once (the valve's current
is off), and a ramp starts again from 0.
"""

from __future__ import annotations

from typing import Any

from ehpss_hil.protocol.cia408.objects import (
    RAMP_LINEAR,
    SCALE_100_PERCENT,
    VPOC_HOLD_SETPOINT,
    VPOC_LOWER_LIMIT,
    VPOC_RAMP_TIME,
    VPOC_RAMP_TYPE,
    VPOC_SETPOINT,
    VPOC_SUB,
    VPOC_UPPER_LIMIT,
    DeviceState,
)

_DRIVEN = (DeviceState.ACTIVE, DeviceState.HOLD)


def _get(store: Any, index: int, sub: int, default: int) -> int:
    return int(store.get(index, sub)) if (index, sub) in store.values else default


class SetpointPath:
    """Target → limits → ramp → demand (module docstring), read from the node's ``store``."""

    def __init__(self, store: Any) -> None:
        self.store = store
        self._ramped = 0.0  # the ramp's demand (set-point units)
        self._t_s: float | None = None

    def target(self, state: DeviceState) -> tuple[int, bool]:
        """The limited target of ``state`` and whether the limits clipped it."""
        st = self.store
        if state is DeviceState.ACTIVE:
            raw = int(st.get(VPOC_SETPOINT, VPOC_SUB))
        elif state is DeviceState.HOLD:
            raw = _get(st, VPOC_HOLD_SETPOINT, VPOC_SUB, 0)
        else:
            return 0, False
        hi = _get(st, VPOC_UPPER_LIMIT, VPOC_SUB, SCALE_100_PERCENT)
        lo = _get(st, VPOC_LOWER_LIMIT, VPOC_SUB, -SCALE_100_PERCENT)
        limited = max(lo, min(hi, raw))
        return limited, limited != raw

    def _ramp_per_s(self) -> float:
        """The ramp's rate (set-point units per s); 0: no ramp."""
        st = self.store
        ms = _get(st, VPOC_RAMP_TIME, VPOC_SUB, 0)
        on = _get(st, VPOC_RAMP_TYPE, 0, 0) == RAMP_LINEAR and ms > 0
        return SCALE_100_PERCENT / (ms * 1e-3) if on else 0.0

    def tick(self, state: DeviceState, t_s: float) -> None:
        """Once per period at loop time ``t_s`` (s): the ramp moves toward the target."""
        dt = 0.0 if self._t_s is None else max(0.0, t_s - self._t_s)
        self._t_s = t_s
        target, _ = self.target(state)
        rate = self._ramp_per_s()
        if state not in _DRIVEN:
            self._ramped = 0.0
        elif rate > 0.0:
            step = rate * dt
            self._ramped = max(self._ramped - step, min(self._ramped + step, float(target)))
        else:
            self._ramped = float(target)

    def demand(self, state: DeviceState) -> float:
        """The demand value (set-point units) the coil current follows now."""
        if state not in _DRIVEN:
            return 0.0
        return self._ramped if self._ramp_per_s() > 0.0 else float(self.target(state)[0])
