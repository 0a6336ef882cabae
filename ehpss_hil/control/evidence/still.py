"""A position sensor that stands still while the spool sits at its stop is dead.

With the spool LVDT at its stop the spool is at the end of its stroke (the plant's stroke and
the LVDT's range coincide) and the piston moves at the valve's full flow: K_c·x_v,max scaled by
k_Q. Every estimator stops taking evidence there (the stop is not evidence of k_LOE, and the
position channel re-anchors x̂ on a trusted sensor), so a sensor that failed or froze while it
was trusted would keep the loop's trust through the whole saturated motion: the loop drives the
spool into its stop towards a reading that never moves, and the piston runs away.

:class:`StillSensor` watches each stop phase in stretches: the spool integral
``K_c·Ts·Σ y_v`` (m, in the units of the model position x̂) against the sensor's own movement
over the stretch. Once the integral has passed ``still_min_travel_m`` while the sensor moved by
less than ``still_fraction`` of it (a live sensor moves by k_DFT·k_Q of it, far more), the
sensor is dead, and the model position is x̂ at the phase start plus the integral since; if the
sensor did move, the next stretch begins there. A mechanically blocked
piston (against its end stop) would look the same; the plant here has no piston end stop.
"""

from __future__ import annotations

from ..tuning import ControlTuning


class StillSensor:
    """One stop phase at a time; :meth:`update` once per fresh sample."""

    __slots__ = ("_fired", "_in_phase", "_kts", "_min_travel", "_still", "_travel", "_x0", "_y0")

    def __init__(self, velocity_gain_1_s: float, ts_s: float, tuning: ControlTuning | None = None) -> None:
        """``velocity_gain_1_s``: K_c (1/s) of the model position; ``ts_s``: sample time (s);
        ``tuning``: ``still_min_travel_m`` and ``still_fraction``."""
        t = tuning if tuning is not None else ControlTuning()
        self._kts = velocity_gain_1_s * ts_s
        self._min_travel = t.still_min_travel_m
        self._still = t.still_fraction
        self.reset()

    def reset(self) -> None:
        """No stop phase in progress."""
        self._in_phase = False
        self._fired = False
        self._travel = self._x0 = self._y0 = 0.0

    def update(self, at_stop: bool, spool_m: float, position_m: float, x_hat_m: float) -> float | None:
        """One fresh sample: the spool LVDT at its stop or not, its reading (m), the position
        sensor (m) and the model position x̂ (m) before any re-anchoring. Returns the model
        position (m) when the sensor is found dead in this phase (once per phase), else None."""
        if not at_stop:
            self._in_phase = False
            return None
        if not self._in_phase:  # x̂ of this sample already holds this sample's spool
            self._in_phase, self._fired = True, False
            self._travel, self._x0, self._y0 = 0.0, x_hat_m, position_m
            return None
        self._travel += self._kts * spool_m
        if self._fired:
            return None
        if abs(self._travel) < self._min_travel:
            return None
        if abs(position_m - self._y0) < self._still * abs(self._travel):
            self._fired = True
            return self._x0 + self._travel
        # the sensor moved over this stretch: judge the next one (a sensor that fails during a
        # long stop phase is caught within two stretches)
        self._x0 += self._travel
        self._y0, self._travel = position_m, 0.0
        return None
