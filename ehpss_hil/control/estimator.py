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

    __slots__ = ("_c", "_g", "_hi", "_lo", "theta", "theta0")

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
