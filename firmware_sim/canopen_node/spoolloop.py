"""The emulated valve's own spool position loop (device control mode 0x6043 = 2) and its
control deviation monitoring (0x6350–0x6353); pure: no bus, loop time passed in.

Closed loop, the demand value is a spool position (±16384 = ±stroke) and the valve computes the
coil current each period from the spool it measured in the period before: a PI law
(:data:`SPOOL_KP_A_PER_M`, :data:`SPOOL_KI_A_PER_M_S`), clipped, with its integral, to the full
scale current. The gains were picked on the plant of params.yaml (spool ω ≈ 2430 rad/s, ζ ≈ 0.7,
sampled at 1 kHz): a +50 % step settles without overshoot within 20 periods.

The control deviation is demand − spool actual value, in set-point units (meaningful closed
loop; open loop it compares a current with a spool position). With monitoring on (0x6351 = 1)
the status word's bit 11 is set while |deviation| has exceeded the threshold 0x6353 for longer
than the delay 0x6352 (ms).
"""

from __future__ import annotations

#: the spool loop's PI gains: A per metre of spool error, and A per metre·second
SPOOL_KP_A_PER_M = 0.02
SPOOL_KI_A_PER_M_S = 20.0


class SpoolLoop:
    """PI from the spool error to the coil current (A), limited to ``full_scale_a``."""

    def __init__(self, full_scale_a: float) -> None:
        self.full_scale_a = full_scale_a
        self.current_a = 0.0
        self._integral_a = 0.0

    def reset(self) -> None:
        """Not driven: no current, the integral cleared."""
        self.current_a = self._integral_a = 0.0

    def step(self, target_m: float, spool_m: float, dt_s: float) -> float:
        """One period: the current (A) for a spool ``target_m`` and the measured ``spool_m``."""
        fs = self.full_scale_a
        error = target_m - spool_m
        self._integral_a = max(-fs, min(fs, self._integral_a + SPOOL_KI_A_PER_M_S * error * dt_s))
        self.current_a = max(-fs, min(fs, SPOOL_KP_A_PER_M * error + self._integral_a))
        return self.current_a


class DeviationMonitor:
    """|deviation| beyond a threshold for longer than a delay (loop time, s)."""

    def __init__(self) -> None:
        self.alarm = False
        self._since_s: float | None = None

    def update(self, on: bool, deviation: int, threshold: int, delay_s: float, t_s: float) -> bool:
        """One period; returns the alarm (status word bit 11)."""
        if not on or abs(deviation) <= threshold:
            self._since_s, self.alarm = None, False
        else:
            if self._since_s is None:
                self._since_s = t_s
            self.alarm = t_s - self._since_s > delay_s
        return self.alarm
