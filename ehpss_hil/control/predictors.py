"""Predictors that run beside the loop: the valve model, the model position x̂ (docs/design.md §5)
and the unit-gain valve + cylinder model the pressure test predicts the load pressure with.

Each is built once (exact ZOH) and steps with plain Python floats: for models of 2–4 states a
hand-written update is several times faster than numpy's small matvec.
"""

from __future__ import annotations

from ..physics.discretize import zoh
from ..physics.model import ACC, SPOOL, SPOOL_VEL, VEL, plant_matrices, valve_matrices
from ..physics.params import PlantParams


class ValvePredictor:
    """2-state exact-ZOH valve model ``[ẋ_v, x_v]`` driven by the applied-current echo.

    The echo received at sample k is the current applied over [k−1, k), so after
    :meth:`step` the state is the commanded spool at sample k (m), independent of k_LOE:
    the spool LVDT then reads ``k_LOE·v``.
    """

    __slots__ = ("_a00", "_a01", "_a10", "_a11", "_b0", "_b1", "_mark", "stop_m", "v", "vel")

    def __init__(self, plant: PlantParams, ts_s: float) -> None:
        a, b = valve_matrices(plant)
        ad, bd = zoh(a, b, ts_s)
        self._a00, self._a01 = float(ad[0, 0]), float(ad[0, 1])
        self._a10, self._a11 = float(ad[1, 0]), float(ad[1, 1])
        self._b0, self._b1 = float(bd[0, 0]), float(bd[1, 0])
        self.vel = 0.0
        self.v = 0.0
        self._mark = (0.0, 0.0)
        #: where the commanded spool stops (m): the stroke over k̂_LOE, set by the controller
        self.stop_m = float("inf")

    def reset(self) -> None:
        """At rest."""
        self.vel = 0.0
        self.v = 0.0
        self._mark = (0.0, 0.0)

    def mark(self) -> None:
        """Remember the state (to :meth:`rewind` to it)."""
        self._mark = (self.vel, self.v)

    def rewind(self) -> None:
        """Back to the state at the last :meth:`mark`."""
        self.vel, self.v = self._mark

    def step(self, current_a: float) -> float:
        """Advance with ``current_a`` (A) held over the last sample; returns v (m), held on the
        stop ±:attr:`stop_m` like the plant's spool (outward velocity lost there)."""
        vel, v = self.vel, self.v
        vel, v = (
            self._a00 * vel + self._a01 * v + self._b0 * current_a,
            self._a10 * vel + self._a11 * v + self._b1 * current_a,
        )
        stop = self.stop_m
        if v > stop or v < -stop:
            v = stop if v > 0.0 else -stop
            if vel * v > 0.0:
                vel = 0.0
        self.vel, self.v = vel, v
        return v


class ModelPosition:
    """Model piston position x̂ (m): trapezoidal integral of ``K_c·spool`` anchored slowly to the
    (compensated) sensor while it is trusted: ``x̂ += Ts·α·(y_s/θ̂_D − x̂)`` (α in rad/s).

    It carries the loop through a position-sensor failure; K_c = flow_gain/hydraulic_stiffness.
    """

    __slots__ = ("_anchor", "_band", "_h", "_mark", "_rate", "_raw", "_ts", "band_gain", "creep_m_s", "x")

    def __init__(self, plant: PlantParams, ts_s: float, anchor_rate_1_s: float, band_m: float = 0.0) -> None:
        """``band_m``: the spool band (m each side of null) :attr:`band_gain` applies in."""
        self._h = 0.5 * ts_s * plant.velocity_gain_1_s
        self._ts = ts_s
        self._anchor = ts_s * anchor_rate_1_s
        self._band = band_m
        #: the share of a spool inside ±band that moves the piston (1: critically lapped; below
        #: 1 once the plant has shown an overlap, :mod:`.evidence.overlap`)
        self.band_gain = 1.0
        #: the piston's velocity with the spool at null (m/s in x̂'s units), integrated beside
        #: the spool
        self.creep_m_s = 0.0
        self.x = 0.0
        self._rate = self._raw = 0.0
        self._mark = (0.0, 0.0, 0.0)

    def reset(self) -> None:
        """At rest at the origin, no creep, no overlap."""
        self.x = 0.0
        self.creep_m_s = 0.0
        self.band_gain = 1.0
        self._rate = self._raw = 0.0
        self._mark = (0.0, 0.0, 0.0)

    def mark(self) -> None:
        """Remember x̂ and the last spool (to :meth:`rewind` to them)."""
        self._mark = (self.x, self._rate, self._raw)

    def rewind(self) -> None:
        """Back to x̂ and the spool at the last :meth:`mark`."""
        self.x, self._rate, self._raw = self._mark

    def integrate(self, spool_m: float) -> float:
        """Trapezoid step with the actual spool at this sample (m) — times :attr:`band_gain`
        inside the band — plus the creep; returns x̂ (m)."""
        self._raw = s = spool_m
        g = self.band_gain
        if g != 1.0 and -self._band < s < self._band:
            s = g * s
        self.x += self._h * (s + self._rate) + self._ts * self.creep_m_s
        self._rate = s
        return self.x

    @property
    def last_spool(self) -> float:
        """The spool (m) of the last :meth:`integrate` (the sample x̂ stands at), as read."""
        return self._raw

    def spool_to_x_m(self, spool_m: float, samples: int) -> float:
        """x̂'s change (m) from a spool of ``spool_m`` (m) held over ``samples`` periods."""
        return samples * (2.0 * self._h * spool_m + self._ts * self.creep_m_s)

    def anchor(self, position_m: float) -> None:
        """Pull x̂ toward a trusted position estimate ``position_m`` = y_s/θ̂_D (m)."""
        self.x += self._anchor * (position_m - self.x)


class UnitPlantPredictor:
    """The valve + cylinder at unit gains (k_LOE = k_Q = 1), driven by the applied-current echo:
    the states ``(ẍ₁, ẋ₁, ẋ_v, x_v)`` of the exact ZOH of the design model, piston position
    left out (nothing depends on it). ``acceleration_m_s2`` ẍ₁ (m/s²) times ``m/A_h`` is the load
    pressure a plant with unit gains gives (:class:`.PressureTest`)."""

    __slots__ = ("_c", "_mark", "s")

    def __init__(self, plant: PlantParams, ts_s: float) -> None:
        a, b = plant_matrices(plant)
        ad, bd = zoh(a, b, ts_s)
        idx = (ACC, VEL, SPOOL_VEL, SPOOL)
        # the rows [A_d row i, B_d row i] one after the other (propagate unpacks them at once)
        self._c = tuple(c for i in idx for c in (*(float(ad[i, j]) for j in idx), float(bd[i, 0])))
        self.reset()

    def reset(self) -> None:
        """At rest."""
        self.s = (0.0, 0.0, 0.0, 0.0)
        self._mark = self.s

    @property
    def acceleration_m_s2(self) -> float:
        """ẍ₁, the piston acceleration at unit gains (m/s²)."""
        return self.s[0]

    def mark(self) -> None:
        """Remember the state (to :meth:`rewind` to it)."""
        self._mark = self.s

    def rewind(self) -> None:
        """Back to the state at the last :meth:`mark`."""
        self.s = self._mark

    def propagate(self, current_a: float) -> None:
        """Advance with ``current_a`` (A) held over the last sample."""
        s0, s1, s2, s3 = self.s
        # the rows' coefficients unpacked at once (one unpack instead of 20 subscripts)
        a00, a01, a02, a03, b0, a10, a11, a12, a13, b1, a20, a21, a22, a23, b2, a30, a31, a32, a33, b3 = (
            self._c
        )
        self.s = (
            a00 * s0 + a01 * s1 + a02 * s2 + a03 * s3 + b0 * current_a,
            a10 * s0 + a11 * s1 + a12 * s2 + a13 * s3 + b1 * current_a,
            a20 * s0 + a21 * s1 + a22 * s2 + a23 * s3 + b2 * current_a,
            a30 * s0 + a31 * s1 + a32 * s2 + a33 * s3 + b3 * current_a,
        )
