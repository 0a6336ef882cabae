"""Phase lock of the controller's deadline grid to the sensor frames' arrival (pure logic).

The emulator (the sensor node) is the bus's time master, like a CANopen SYNC producer; two free
grids of the same period have a random phase, so a sensor frame would wait up to a whole period
before the controller picks it up (sensor→command latency uniform in [0, T)). The controller keeps
its fixed grid (``next += period``) but slews it by at most ``max_slew_s`` per cycle so that its
deadline falls ``target_age_s`` after the sensor frame arrives: the frame's age at the deadline
is driven to the target, and the latency becomes target + compute time. The first correction
(the first sensor frame, the controller still CONFIGURED) aligns the grid at once.

The age error is wrapped into [−T/2, T/2): a frame that just missed a deadline (age ≈ T) reads as
a small negative error, so the lock pulls the grid back instead of a whole period forward.
"""

from __future__ import annotations


class PhaseLock:
    """Deadline corrections (s) from sensor frame ages; ``gain`` per cycle, bounded slew."""

    def __init__(
        self, period_s: float, target_age_s: float, gain: float = 0.1, max_slew_s: float | None = None
    ) -> None:
        if not 0.0 <= target_age_s < period_s:
            raise ValueError("target_age_s must be in [0, period_s)")
        if not 0.0 < gain <= 1.0:
            raise ValueError("gain must be in (0, 1]")
        self.period_s = period_s
        self.target_age_s = target_age_s
        self.gain = gain
        self.max_slew_s = 0.02 * period_s if max_slew_s is None else max_slew_s
        self.last_age_s = float("nan")
        self.locked = False

    def error(self, age_s: float) -> float:
        """Wrapped age error (s): positive = the deadline comes too long after the arrival."""
        t = self.period_s
        return (age_s - self.target_age_s + 0.5 * t) % t - 0.5 * t

    def correction(self, deadline_s: float, arrival_s: float) -> float:
        """Shift (s) to add to the next deadline, given this cycle's deadline and the arrival
        time of the newest sensor frame it used (same clock)."""
        age = deadline_s - arrival_s
        self.last_age_s = age
        if not self.locked:  # the first frame: align at once (nothing runs yet to disturb)
            self.locked = True
            return -self.error(age)
        c = -self.gain * self.error(age)
        return max(-self.max_slew_s, min(self.max_slew_s, c))
