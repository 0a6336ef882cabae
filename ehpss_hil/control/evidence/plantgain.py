"""What the pressure test knows of the plant itself: its own flow gain and its pressure gain.

A plant is never the model: its flow gain may be off the model's within
``velocity_gain_uncertainty`` without any fault. Until the plant has shown its own, a deviation
of the product θ_pos = k_DFT·k_Q inside that uncertainty may be the plant's and not a change:
:class:`PlantGain` adopts such a deviation as the plant's flow gain :attr:`PlantGain.k_base` (the
nominal of both hypotheses of :class:`.PressureTest`) when the window held it undecided, and
marks the plant as seen at the model's gain once the averaged product stood at 1 for
``plant_seen_s``; after either, a deviation is a change. It also holds the plant's load-pressure
gain learned while nothing deviates (:class:`.PressureBaseline`). :class:`ProductAverage` is θ_pos
averaged over about M excited increments and its wander. All gains are dimensionless.
"""

from __future__ import annotations

from ..tuning import ControlTuning
from .baseline import PressureBaseline


class ProductAverage:
    """θ_pos averaged over about M excited updates (the gain H_Q is judged with: one θ_pos
    wanders with the position noise) and the mean step between updates (that wander)."""

    __slots__ = ("_m", "_prev", "_spread", "mean", "wander")

    def __init__(self, m: int, spread: float) -> None:
        """``m``: the number of excited updates averaged over (``increment_window``);
        ``spread``: the mean steps the product's own wander may take it (``product_spread``)."""
        self._m = m
        self._spread = spread
        self.reset()

    def reset(self) -> None:
        """At the model's gain, no wander."""
        #: the averaged product
        self.mean = 1.0
        #: the mean |step| of θ_pos between excited updates
        self.wander = 0.0
        self._prev = 1.0

    def add(self, theta_pos: float) -> None:
        """One excited update of θ_pos."""
        m = self._m
        self.mean += (theta_pos - self.mean) / m
        self.wander += (abs(theta_pos - self._prev) - self.wander) / m
        self._prev = theta_pos

    @property
    def reach(self) -> float:
        """How far the product's own wander may take it: ``product_spread`` mean steps."""
        return self._spread * self.wander


class PlantGain:
    """The plant's own flow gain :attr:`k_base`, whether the plant was seen at the model's
    (:attr:`seen`), and its pressure gain (:attr:`baseline`); kept across a fail-safe recovery,
    forgotten at power-on (:meth:`forget`)."""

    __slots__ = (
        "_band",
        "_count",
        "_failed_below",
        "_min_dev",
        "_seen_n",
        "_vband",
        "baseline",
        "k_base",
        "seen",
    )

    def __init__(self, ts_s: float, tuning: ControlTuning) -> None:
        """``ts_s``: sample time (s); ``tuning``: ``plant_seen_s``, the uncertainties, the
        ``baseline_*`` fields."""
        t = tuning
        #: the plant's load pressure over the model's, learned while nothing deviates
        self.baseline = PressureBaseline(ts_s, t)
        self._band = t.pressure_gain_uncertainty
        self._vband = t.velocity_gain_uncertainty
        self._min_dev = t.flow_gain_min_deviation
        self._failed_below = t.sensor_failed_below
        self._seen_n = max(1, round(t.plant_seen_s / ts_s))
        self.forget()

    def forget(self) -> None:
        """Nothing known of the plant (power-on): the model's flow gain, not seen yet, no
        pressure baseline."""
        #: the plant's own flow gain (the product's healthy value, learned at power-on): the
        #: nominal of both hypotheses; 1 until a deviation inside the uncertainty is adopted
        self.k_base = 1.0
        #: the averaged product stood at 1 for ``plant_seen_s``: the plant runs at the model's
        #: flow gain, and no later deviation is adopted as its own
        self.seen = False
        self._count = 0  # excited updates in a row with the averaged product at 1
        self.baseline.forget()

    def observe(self, mean: float) -> None:
        """An excited update with the averaged product at ``mean``: counts towards :attr:`seen`."""
        if abs(mean - 1.0) < self._min_dev:
            self._count += 1
            if self._count >= self._seen_n:
                self.seen = True
        else:
            self._count = 0

    @property
    def known(self) -> bool:
        """The plant has shown its own flow gain: seen at the model's, a pressure baseline
        learned, or its own adopted."""
        return self.seen or self.baseline.learned or self.k_base != 1.0

    def adopt(self, avg: ProductAverage, theta: float) -> bool:
        """Adopt the averaged product as the plant's flow gain when it lies within the
        velocity-gain uncertainty, beyond its own wander and beyond ``min_deviation``, and the
        plant has not shown its own yet (:attr:`known`); ``theta``: this sample's θ_pos (no
        adoption from a failed sensor's). Returns whether it was adopted."""
        if self.known:
            return False
        dev = abs(avg.mean - 1.0)
        inside = avg.reach < dev <= self._vband and dev >= self._min_dev
        if inside and theta >= self._failed_below:
            self.k_base = avg.mean
            return True
        return False

    def fault_possible(self, theta: float) -> bool:
        """Whether H_D may be decided for an averaged product at ``theta``: the load pressure
        tells a sensor gain from a flow gain only against the plant's own pressure gain, which
        the model error moves (ω_h² moves the product and leaves the pressure's high band
        alone; the window's ratio depends on the frequencies the loop excites). So while that
        gain is uncertain (``pressure_gain_uncertainty`` > 0) and not learned
        (:attr:`baseline`), a deviation within ``velocity_gain_uncertainty`` of the plant's flow
        gain :attr:`k_base` is left undecided (and adopted as the plant's when it stays so, while
        the plant is not :attr:`known`); one beyond it is a fault. Having seen the product at the
        model's gain is not enough: a flow-gain ramp from a plant off the model passes through 1
        on its way."""
        if self._band == 0.0 or self.baseline.learned:
            return True
        return abs(theta - self.k_base) > self._vband
