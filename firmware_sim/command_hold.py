"""The valve amplifier's command input: newest valid VALVE_CMD held, timeout counted in periods.

No valid command for ``timeout_periods`` periods → applied setpoint 0 A and the CmdTimeout flag;
a fresh valid command ends the timeout at once. The emulator starts timed out (no command yet).
"""

from __future__ import annotations

import logging

log = logging.getLogger(__name__)


class CommandHold:
    """Holds the last valid coil current setpoint (A) and its enable bit."""

    def __init__(self, timeout_periods: int) -> None:
        if timeout_periods < 1:
            raise ValueError("timeout_periods must be >= 1")
        self.timeout_periods = timeout_periods
        self.current_a = 0.0
        self.enable = False
        self.periods_since = timeout_periods
        self.timed_out = True
        self.timeouts = 0
        self.accepted = 0
        self._fresh = False

    def accept(self, current_a: float, enable: bool) -> None:
        """A valid VALVE_CMD arrived this period."""
        self.current_a = current_a
        self.enable = enable
        self._fresh = True
        self.accepted += 1

    def tick(self, t_s: float = 0.0) -> float:
        """Close one period; returns the setpoint to apply over the next one (A)."""
        if self._fresh:
            self.periods_since = 0
            self._fresh = False
        else:
            self.periods_since += 1
        was = self.timed_out
        self.timed_out = self.periods_since >= self.timeout_periods
        if self.timed_out and not was:
            self.timeouts += 1
            log.warning(
                "t=%.4f s: no valid VALVE_CMD for %d periods: applied current 0 A", t_s, self.periods_since
            )
        elif was and not self.timed_out and self.accepted > 1:
            log.info("t=%.4f s: VALVE_CMD fresh again, command timeout cleared", t_s)
        return self.setpoint_a

    @property
    def setpoint_a(self) -> float:
        """The current to apply now (A): 0 when timed out or disabled."""
        if self.timed_out or not self.enable:
            return 0.0
        return self.current_a

    @property
    def valve_enabled(self) -> bool:
        """SENSOR_AUX ValveEnabled."""
        return self.enable and not self.timed_out
