"""Normalized-gradient (NLMS) parameter estimators — the corrected form of the paper's eq 38.

``θ ← clip(θ + g·ε·φ/(c + φ²))`` with ``ε = y − θ·φ`` (a priori), ``c = (c_frac·S)²`` and the per
sample gain ``g = 1 − (1 − γ)^(Ts/1 ms)`` (γ = 0.2 per millisecond), so the convergence per unit
time does not depend on the sample rate. All quantities are dimensionless gains or SI signals.
"""

from __future__ import annotations


def per_sample_gain(gain_per_ms: float, ts_s: float) -> float:
    """NLMS step per sample for a contraction ``gain_per_ms`` per millisecond (dimensionless)."""
    return 1.0 - (1.0 - gain_per_ms) ** (ts_s / 1e-3)


class Nlms:
    """Scalar NLMS estimator of θ in ``y = θ·φ``, clipped to ``[lo, hi]``."""

    __slots__ = ("theta", "theta0", "_g", "_c", "_lo", "_hi")

    def __init__(self, theta0: float, gain: float, c: float, lo: float, hi: float) -> None:
        self.theta0 = theta0
        self.theta = theta0
        self._g = gain
        self._c = c
        self._lo = lo
        self._hi = hi

    def reset(self) -> None:
        """Back to the initial θ."""
        self.theta = self.theta0

    def update(self, y: float, phi: float) -> float:
        """One step; returns the a priori residual ``ε = y − θ·φ`` (units of y)."""
        eps = y - self.theta * phi
        t = self.theta + self._g * eps * phi / (self._c + phi * phi)
        self.theta = self._lo if t < self._lo else self._hi if t > self._hi else t
        return eps


class BilinearNlms:
    """NLMS on ``y = θ_L·θ_D·φ`` (the paper's joint actuator/sensor parametrization).

    Only the product is identifiable from the position alone; the gradient splits each correction
    between θ_L and θ_D in proportion to the other factor.
    """

    __slots__ = ("theta_l", "theta_d", "_g", "_c", "_lim_l", "_lim_d")

    def __init__(self, gain: float, c: float, lim_l: tuple[float, float],
                 lim_d: tuple[float, float]) -> None:
        self._g = gain
        self._c = c
        self._lim_l = lim_l
        self._lim_d = lim_d
        self.theta_l = 1.0
        self.theta_d = 1.0

    def reset(self) -> None:
        """Back to the nominal (1, 1)."""
        self.theta_l = 1.0
        self.theta_d = 1.0

    def update(self, y: float, phi: float) -> float:
        """One step; returns the a priori residual ``y − θ_L·θ_D·φ``."""
        tl, td = self.theta_l, self.theta_d
        eps = y - tl * td * phi
        gl, gd = td * phi, tl * phi
        k = self._g * eps / (self._c + gl * gl + gd * gd)
        lo, hi = self._lim_l
        tl += k * gl
        self.theta_l = lo if tl < lo else hi if tl > hi else tl
        lo, hi = self._lim_d
        td += k * gd
        self.theta_d = lo if td < lo else hi if td > hi else td
        return eps
