"""The plant's own load-pressure gain, learned while nothing deviates: the pressure test's baseline.

A plant whose hydraulic natural frequency or load mass is off the model answers the same current
with another load pressure; a test judged against the model's own pressure takes that for a
flow-gain change. :class:`PressureBaseline` fits ``P_L = g·(k̂_LOE·u)`` by least squares over an
exponentially weighted window (``baseline_window_s``) of healthy samples — the spool channel
settled, nothing deviating, no sensor attribution (the caller's judgement,
:meth:`.PressureTest.update`). Until ``baseline_min_s`` of them were seen the gain is unknown
(1, and the test judges each hypothesis within ``pressure_gain_uncertainty``); then it is the
fitted gain within ``baseline_limits``, where it is off 1 by more than ``baseline_deadband``.
Units: u = (m/A_h)·ẍ₁ in Pa per unit gain, P_L in Pa; the gain is dimensionless.
"""

from __future__ import annotations

import math

from ..tuning import ControlTuning


class PressureBaseline:
    """Σw·u², Σw·u·P_L and Σw of the healthy samples, and the gain they give."""

    __slots__ = ("_d", "_dead", "_hi", "_lo", "_min", "_up", "_uu", "weight")

    def __init__(self, ts_s: float, tuning: ControlTuning) -> None:
        """``ts_s``: sample time (s); ``tuning``: the ``baseline_*`` fields."""
        self._d = math.exp(-ts_s / tuning.baseline_window_s)
        self._min = tuning.baseline_min_s / ts_s
        self._lo, self._hi = tuning.baseline_limits[0], tuning.baseline_limits[1]
        self._dead = tuning.baseline_deadband
        self.forget()

    def forget(self) -> None:
        """Nothing learned (power-on)."""
        self._uu = self._up = 0.0
        #: the window's weight Σw (samples)
        self.weight = 0.0

    def learn(self, u: float, pressure_pa: float) -> None:
        """One healthy sample: the predicted pressure per unit gain ``u`` = k̂_LOE·(m/A_h)·ẍ₁
        and the measured P_L (Pa)."""
        d = self._d
        self._uu = d * self._uu + u * u
        self._up = d * self._up + u * pressure_pa
        self.weight = d * self.weight + 1.0

    @property
    def learned(self) -> bool:
        """``baseline_min_s`` of healthy samples were seen."""
        return self.weight >= self._min

    @property
    def gain(self) -> float:
        """The plant's load pressure over the model's: 1 until :attr:`learned`, then the
        least-squares gain within ``baseline_limits``, where it is off 1 by more than
        ``baseline_deadband``."""
        if self.weight < self._min or self._uu <= 0.0:
            return 1.0
        g = min(max(self._up / self._uu, self._lo), self._hi)
        return g if abs(g - 1.0) > self._dead else 1.0
