"""The piston's velocity with the spool at null (creep): a plant property the linear model leaves out.

The design model moves the piston with the spool alone, ``ẋ = K_c·y_v``. A real cylinder also
moves with the spool at null: a load or a spring pushes oil through the leakage, a single-rod
cylinder's unequal areas leave a net force when both chambers leak to the same pressure, a spool
null offset lets oil through (docs/physics.md "Nonlinear plant"). Left out, the creep is read as
a gain: the single-rod plant's 5 mm/s put the increment gain θ_prod at 2.4 at power-on, then at 0
as the spool reversed, and x̂ — integrating the spool alone — walked away from the piston.

:class:`CreepEstimator` measures it where no gain can hide it: over increments taken while the
spool was near null (``|φ/τ|`` below ``creep_null_share`` of the full-flow velocity), the position
moves by ``c·τ`` plus what the gain makes of the little flow there, ``θ·φ``. So the creep is the
exponentially weighted mean of ``(Δy − θ_prod·φ)/τ`` over such increments — whatever the sensor's
gain or the flow gain (both multiply a flow near zero). A jump of the reading is no creep: an
increment further than ``creep_outlier_sigmas`` spreads from the mean is left out. The creep is
used once it exceeds ``creep_min_share`` of the full-flow velocity (the smallest worth
modelling; a linear plant's stays far below) and stays in use until it falls below half of that.
"""

from __future__ import annotations

import math

from ..tuning import ControlTuning


class CreepEstimator:
    """Creep c (m/s of the sensor reading) from near-null increments ``(Δy, φ, τ)``."""

    __slots__ = ("_min_n", "_n", "_n_avg", "_null", "_on", "_out2", "_var", "_w", "mean_m_s", "rate_m_s")

    def __init__(self, full_flow_m_s: float, tuning: ControlTuning | None = None) -> None:
        """``full_flow_m_s``: the piston velocity at the full spool stroke, nominal flow gain
        (m/s); ``tuning``: the ``creep_*`` gates."""
        t = tuning if tuning is not None else ControlTuning()
        self._null = t.creep_null_share * full_flow_m_s
        self._on = t.creep_min_share * full_flow_m_s
        self._n_avg = t.creep_samples
        self._min_n = t.creep_min_samples
        self._out2 = t.creep_outlier_sigmas * t.creep_outlier_sigmas
        self._w = 1.0 / t.creep_samples
        self.reset()

    def reset(self) -> None:
        """No creep, no samples."""
        self._n = 0
        self._var = 0.0
        #: the mean of the near-null velocities (m/s)
        self.mean_m_s = 0.0
        #: the creep in use: the mean once it is worth modelling, else 0 (m/s)
        self.rate_m_s = 0.0

    def update(self, dy_m: float, phi_m: float, tau_s: float, theta: float) -> float:
        """One increment: position increment Δy (m), spool-integral increment φ (m, nominal flow
        gain), the time it spans τ (s), the gain θ_prod. Returns the creep in use (m/s)."""
        if tau_s <= 0.0 or abs(phi_m) > self._null * tau_s:
            return self.rate_m_s
        v = (dy_m - theta * phi_m) / tau_s
        n, m, var = self._n, self.mean_m_s, self._var
        d = v - m
        if n >= self._min_n and d * d > self._out2 * var:
            return self.rate_m_s
        n += 1
        w = 1.0 / n if n < self._n_avg else self._w
        m += w * d
        var += w * (d * (v - m) - var)
        self._n, self.mean_m_s, self._var = n, m, var
        if n >= self._min_n:
            on = abs(m) > (0.5 * self._on if self.rate_m_s else self._on)
            self.rate_m_s = m if on else 0.0
        return self.rate_m_s

    @property
    def null_m_s(self) -> float:
        """The velocity (m/s, nominal flow gain) below which a spool counts as near null."""
        return self._null

    @property
    def judged(self) -> bool:
        """Enough near-null increments have been seen to say whether the plant creeps."""
        return self._n >= self._min_n

    @property
    def spread_m_s(self) -> float:
        """The spread of the near-null velocities about the mean (m/s)."""
        return math.sqrt(max(self._var, 0.0))
