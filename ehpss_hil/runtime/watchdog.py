"""Sensor watchdog (DESIGN.md §8): pure logic, one :meth:`SensorWatchdog.update` per cycle.

A cycle is *fresh* when a usable SENSOR_POS frame arrived in it. ``timeout_cycles`` cycles in a
row without one trip the watchdog, with the reason taken from what did arrive meanwhile:
implausible frames → PLAUSIBILITY, frames failing E2E (CRC, sequence, DLC) → E2E_ERRORS, nothing →
SENSOR_TIMEOUT. ``max_e2e_errors`` E2E failures without a usable frame in between trip it too
(E2E_ERRORS). Once tripped it stays tripped until ``recovery_cycles`` fresh cycles in a row have
passed, and then only if ``auto_recover`` is set.
"""

from __future__ import annotations

from ..config import Watchdog
from .lifecycle import FailsafeReason


class SensorWatchdog:
    """Counts cycles; ``tripped``/``reason`` say whether the loop must be in fail-safe."""

    def __init__(self, cfg: Watchdog) -> None:
        self.cfg = cfg
        self.reset()

    def reset(self) -> None:
        """Healthy, counters cleared."""
        self.tripped = False
        self.reason = FailsafeReason.NONE
        self.stale_cycles = 0
        self.fresh_cycles = 0
        self.e2e_errors = 0
        self._streak_e2e = 0
        self._streak_implausible = 0
        self.trips = 0

    def update(self, fresh: bool, e2e_errors: int = 0, implausible: int = 0) -> bool:
        """Account one cycle; ``e2e_errors``/``implausible`` = sensor frames rejected this cycle
        for E2E/DLC resp. range reasons. Returns True when the loop must be in fail-safe."""
        if fresh:
            self.stale_cycles = 0
            self.fresh_cycles += 1
            self.e2e_errors = 0
            self._streak_e2e = 0
            self._streak_implausible = 0
            if e2e_errors:  # rejected frames next to a good one still count toward the burst
                self.e2e_errors = e2e_errors
        else:
            self.stale_cycles += 1
            self.fresh_cycles = 0
            self.e2e_errors += e2e_errors
            self._streak_e2e += e2e_errors
            self._streak_implausible += implausible
        if not self.tripped:
            reason = self._trip_reason()
            if reason is not FailsafeReason.NONE:
                self.tripped = True
                self.reason = reason
                self.trips += 1
        elif self.cfg.auto_recover and self.fresh_cycles >= self.cfg.recovery_cycles:
            self.tripped = False
            self.reason = FailsafeReason.NONE
        return self.tripped

    def _trip_reason(self) -> FailsafeReason:
        if self.e2e_errors >= self.cfg.max_e2e_errors:
            return FailsafeReason.E2E_ERRORS
        if self.stale_cycles < self.cfg.timeout_cycles:
            return FailsafeReason.NONE
        if self._streak_implausible:
            return FailsafeReason.PLAUSIBILITY
        if self._streak_e2e:
            return FailsafeReason.E2E_ERRORS
        return FailsafeReason.SENSOR_TIMEOUT
