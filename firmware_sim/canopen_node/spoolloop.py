"""The emulated valve's own spool position loop (device control mode 0x6043 = 2) and its
control deviation monitoring (0x6350–0x6355); pure: no bus, loop time passed in.

Closed loop, the demand value is a spool position (±16384 = ±stroke) and the valve computes the
coil current each period from the spool it measured in the period before: a PI law
(:data:`SPOOL_KP_A_PER_M`, :data:`SPOOL_KI_A_PER_M_S`), clipped, with its integral, to the full
scale current. The gains were picked on the plant of params.yaml (spool ω ≈ 2430 rad/s, ζ ≈ 0.7,
sampled at 1 kHz): a +50 % step settles without overshoot within 20 periods.

The control deviation is demand − spool actual value, in set-point units (meaningful closed
loop; open loop it compares a current with a spool position). The monitoring type 0x6351 picks
the band the deviation must stay in: 1 the symmetric band ±0x6353, 2 the window [0x6355 lower,
0x6354 upper] (an asymmetric band, e.g. tighter on the side where an overshoot hurts; lower >
upper is an empty window: always outside). The status word's bit 11 is set while the deviation
has been outside the band for longer than the delay 0x6352 (ms); 0 switches monitoring off.
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
    """The deviation outside a band [lower, upper] for longer than a delay (loop time, s)."""

    def __init__(self) -> None:
        self.alarm = False
        self._since_s: float | None = None

    def update(self, band: tuple[int, int] | None, deviation: int, delay_s: float, t_s: float) -> bool:
        """One period with the band ``(lower, upper)`` in set-point units (None: monitoring off);
        returns the alarm (status word bit 11)."""
        if band is None or band[0] <= deviation <= band[1]:
            self._since_s, self.alarm = None, False
        else:
            if self._since_s is None:
                self._since_s = t_s
            self.alarm = t_s - self._since_s > delay_s
        return self.alarm
