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

Until the near-null mean is judged (``creep_min_samples`` near-null increments: a sine's first
stroke reaches null only at its peak) the creep is also fitted **jointly with the gain**,
``Δy = θ·φ + c·τ``, by least squares over non-overlapping increments
(:meth:`CreepEstimator.joint`): identifiable as soon as the velocity varies, which a start from
rest always does. The joint fit judges the creep once its standard error is below
``creep_joint_se`` of the smallest creep modelled; a creep it finds then is used the same way,
and the near-null mean takes over once it is judged.
"""

from __future__ import annotations

import math

from ..tuning import ControlTuning


class CreepEstimator:
    """Creep c (m/s of the sensor reading) from near-null increments ``(Δy, φ, τ)``."""

    __slots__ = (
        "_j",
        "_jclosed",
        "_jfit",
        "_jmax",
        "_jmin",
        "_jn",
        "_joint_judged",
        "_min_n",
        "_n",
        "_n_avg",
        "_null_speed_m_s",
        "_on",
        "_out2",
        "_se_max",
        "_var",
        "_w",
        "mean_m_s",
        "rate_m_s",
    )

    def __init__(self, full_flow_m_s: float, tuning: ControlTuning | None = None) -> None:
        """``full_flow_m_s``: the piston velocity at the full spool stroke, nominal flow gain
        (m/s); ``tuning``: the ``creep_*`` gates."""
        t = tuning if tuning is not None else ControlTuning()
        self._null_speed_m_s = t.creep_null_share * full_flow_m_s
        self._on = t.creep_min_share * full_flow_m_s
        self._n_avg = t.creep_samples
        self._min_n = t.creep_min_samples
        self._out2 = t.creep_outlier_sigmas * t.creep_outlier_sigmas
        self._w = 1.0 / t.creep_samples
        self._se_max = t.creep_joint_se * self._on
        self._jmin = max(3, t.creep_joint_min)
        self._jmax = t.creep_joint_max
        self.reset()

    def reset(self) -> None:
        """No creep, no samples."""
        self._n = 0
        self._var = 0.0
        # the joint fit's sums Σφ², Σφτ, Στ², Σφy, Στy, Σy² and its count
        self._j = [0.0] * 6
        self._jn = 0
        self._jfit = (0.0, 0.0, -1.0)  # the joint fit's θ, c (m/s) and residual variance (m²; <0: none)
        self._joint_judged = False
        self._jclosed = False  # the reading jumped, or an increment did not fit: closed
        #: the mean of the near-null velocities (m/s)
        self.mean_m_s = 0.0
        #: the creep in use: the mean once it is worth modelling, else 0 (m/s)
        self.rate_m_s = 0.0

    def update(self, dy_m: float, phi_m: float, tau_s: float, theta: float) -> float:
        """One increment: position increment Δy (m), spool-integral increment φ (m, nominal flow
        gain), the time it spans τ (s), the gain θ_prod. Returns the creep in use (m/s)."""
        if tau_s <= 0.0 or abs(phi_m) > self._null_speed_m_s * tau_s:
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

    def joint(self, dy_m: float, phi_m: float, tau_s: float, noise_var_m2: float) -> None:
        """One non-overlapping increment for the joint fit ``Δy = θ·φ + c·τ`` (m, m, s), while it
        is open (:attr:`joint_open`); ``noise_var_m2``: the reading's increment noise variance
        (m², the floor of the fit's residual variance). From ``creep_joint_min`` increments on,
        an increment further than ``creep_outlier_sigmas`` residual spreads from the fit (a
        sensor that jumped, failed or stuck) is left out and closes the fit (the increments
        after it, a stuck reading's near a reversal among them, may fit it again). Once the
        fit's creep is known within ``creep_joint_se`` of the smallest creep modelled it is
        judged and closes: a creep above that smallest one is used (:attr:`rate_m_s`)."""
        theta, c, s2 = self._jfit
        if s2 >= 0.0:
            r = dy_m - theta * phi_m - c * tau_s
            if r * r > self._out2 * s2:  # what follows may not be the plant either: closed
                self._jclosed = True
                return
        j = self._j
        j[0] += phi_m * phi_m
        j[1] += phi_m * tau_s
        j[2] += tau_s * tau_s
        j[3] += phi_m * dy_m
        j[4] += tau_s * dy_m
        j[5] += dy_m * dy_m
        n = self._jn = self._jn + 1
        if n < self._jmin:
            return
        det = j[0] * j[2] - j[1] * j[1]
        if not det > 0.0:  # the velocity has not varied: c is not identifiable
            return
        c = (j[0] * j[4] - j[1] * j[3]) / det
        theta = (j[2] * j[3] - j[1] * j[4]) / det
        s2 = max(j[5] - theta * j[3] - c * j[4], 0.0) / (n - 2)
        if s2 < noise_var_m2:
            s2 = noise_var_m2
        self._jfit = (theta, c, s2)
        if s2 * j[0] / det < self._se_max * self._se_max:
            self._joint_judged = True
            self.rate_m_s = c if abs(c) > self._on else 0.0

    @property
    def joint_fit(self) -> tuple[float, float]:
        """The joint fit's gain θ and creep c (m/s) so far (0, 0 before its minimum)."""
        return self._jfit[0], self._jfit[1]

    @property
    def joint_open(self) -> bool:
        """The joint fit still takes increments: neither it nor the near-null mean has judged,
        the reading has not jumped, no increment was an outlier, and it has not run for
        ``creep_joint_max`` increments."""
        return not (self._joint_judged or self._jclosed) and self._jn < self._jmax and self._n < self._min_n

    def close_joint(self) -> None:
        """The reading jumped: the joint fit takes no more increments (a gain change would be
        read as a creep)."""
        self._jclosed = True

    @property
    def null_m_s(self) -> float:
        """The velocity (m/s, nominal flow gain) below which a spool counts as near null."""
        return self._null_speed_m_s

    @property
    def judged(self) -> bool:
        """Enough increments have been seen to say whether the plant creeps: near null, or
        the joint fit's creep is known."""
        return self._n >= self._min_n or self._joint_judged

    @property
    def spread_m_s(self) -> float:
        """The spread of the near-null velocities about the mean (m/s)."""
        return math.sqrt(max(self._var, 0.0))
