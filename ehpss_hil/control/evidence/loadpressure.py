"""The pressure test's evidence: the load pressure against a unit-gain model, over one window.

The load pressure does not go through the position sensor: ``P_L = k_LOE·k_Q·(m/A_h)·ẍ₁``, ẍ₁
the acceleration of a unit-gain model of the valve and cylinder driven by the applied-current
echo (:class:`.UnitPlantPredictor`, stepped by the sample clock). :class:`LoadPressure` keeps
that model, the exponentially weighted window of P_L against its prediction
(:class:`.PressureWindow`), and what the window's samples are about: the k̂_LOE they were taken
with and the averaged product when the window began. Evidence taken about another plant (the
LOE moved, the product moved off the deviation the window held) is dropped; after samples the
model was stepped through without their data, none is taken for a while (:meth:`hold_off`).
Which hypotheses the window is judged with is :class:`.PressureTest`'s. Units: P_L in Pa, the
prediction per unit gain ``u = (m/A_h)·ẍ₁`` in Pa, gains dimensionless.
"""

from __future__ import annotations

import math

from ...physics.params import PlantParams
from ..predictors import UnitPlantPredictor
from ..tuning import ControlTuning
from .baseline import PressureBaseline
from .likelihood import PressureWindow


class LoadPressure:
    """The unit-gain P_L model (:attr:`model`), the evidence :attr:`window`, the hold-off, the
    k̂_LOE and the product the window's samples are about."""

    __slots__ = ("_hold", "_min_dev", "_pa", "_tl_ref", "_tq_ref", "_undecided", "model", "window")

    def __init__(self, plant: PlantParams, ts_s: float, tuning: ControlTuning) -> None:
        t = tuning
        #: the valve + cylinder at unit gains, stepped on the current echo by the sample clock
        self.model = UnitPlantPredictor(plant, ts_s)
        #: P_L against the unit-gain prediction, over ``flow_gain_window_s``
        self.window = PressureWindow(math.exp(-ts_s / t.flow_gain_window_s))
        self._pa = plant.load_mass_kg / plant.piston_area_m2
        self._min_dev = t.flow_gain_min_deviation
        self._undecided = t.undecided_evidence * (t.flow_gain_min_evidence_s / ts_s)
        self.reset()

    def reset(self) -> None:
        """At rest, no evidence, nothing held off, k̂_LOE not settled."""
        self.model.reset()
        self._hold = 0
        self._tl_ref = math.nan  # the settled k̂_LOE a move is measured from (NaN: not settled yet)
        self.restart()

    def restart(self) -> None:
        """Empty the window (what it held is about another deviation or plant)."""
        self.window.empty()
        self._tq_ref = 1.0  # the product the window's evidence is about (set by its first sample)

    def hold_off(self, samples: int) -> None:
        """Take no evidence for the next ``samples`` samples: after samples the model was stepped
        through without their data its P_L prediction is off until the valve and cylinder
        dynamics forget the error, and a prediction error favours the hypothesis with the smaller
        gain — a false H_Q."""
        self._hold = max(self._hold, samples)

    def held(self) -> bool:
        """Whether this sample is held off (counted down)."""
        if self._hold > 0:
            self._hold -= 1
            return True
        return False

    def loe_moved(self, theta_l: float, healthy: bool) -> bool:
        """Follow the settled k̂_LOE ``theta_l``: set once the spool channel is ``healthy``;
        returns whether it moved beyond ``flow_gain_min_deviation`` off it since (a change of the
        LOE: the window's samples from before it are about another plant, since its
        k̂_LOE-free sums would weigh them with the new k̂_LOE)."""
        tl_ref = self._tl_ref
        if tl_ref != tl_ref:  # NaN: k̂_LOE not yet settled since the reset (being identified)
            if healthy:
                self._tl_ref = theta_l
        elif abs(theta_l - tl_ref) > self._min_dev * tl_ref:
            self._tl_ref = theta_l
            return True
        return False

    @property
    def undecided(self) -> bool:
        """The window holds ``undecided_evidence`` times the minimum evidence: a deviation it
        held that long without a decision is ambiguous about it."""
        return self.window.w >= self._undecided

    def moved_off(self, mean: float) -> bool:
        """The averaged product ``mean`` moved beyond ``flow_gain_min_deviation`` off the one the
        window's evidence is about, after the window held it :attr:`undecided`."""
        return self.undecided and not abs(mean - self._tq_ref) <= self._min_dev

    def add(self, pressure_pa: float, mean: float) -> None:
        """One sample of evidence: the measured P_L (Pa) against the model's prediction; the
        averaged product ``mean`` is what the evidence is about when the window was empty."""
        win = self.window
        if win.w == 0.0:
            self._tq_ref = mean
        win.add(self._pa * self.model.acceleration_m_s2, pressure_pa)

    def teach(self, baseline: PressureBaseline, gain: float, pressure_pa: float) -> None:
        """One healthy sample into the plant's pressure ``baseline``: the model's prediction at
        ``gain`` (k̂_LOE·k_base) against the measured P_L (Pa)."""
        baseline.learn(gain * self._pa * self.model.acceleration_m_s2, pressure_pa)
