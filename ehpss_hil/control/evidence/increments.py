"""The increment product θ_prod: the offset-free estimate of k_DFT·k_Q from position increments.

With the piston position and the spool LVDT alone only the product ``k_DFT·k_Q`` is identifiable.
:class:`Increments` estimates it by NLMS on M-sample increments of the position reading against
the running spool integral ``K_c·∫y_v`` (m of piston travel at the nominal flow gain): a k_Q
change leaves x̂ with a level offset, increments have none. An increment is evidence only while
it is excited — above the excitation gate (``flow_gain_excitation`` of the nominal increment
K_c·S·M·Ts) and above ``excitation_snr`` times the reading's one-sample noise, estimated online
about what the spool explains — and the spool was not at its stop. The creep (:mod:`.creep`)
learns from the increments taken near null, and its share is taken out of each increment.

What it gives the other evidence: θ_prod, whether it is fresh (an excited increment within the
last M updates) and settled (M excited updates within ``min_deviation``/2 of where they began),
the samples since the reading last moved (a stuck sensor never does), and the spool and creep
integrals the jump test compares the reading with.
"""

from __future__ import annotations

import math

from ...physics.params import PlantParams
from ..estimator import per_sample_gain
from ..tuning import ControlTuning
from .creep import CreepEstimator


class Increments:
    """θ_prod and its companions, one :meth:`product` call per fresh sample.

    ``scale_m``: the nominal spool amplitude S (m); it sets the excitation gate and the NLMS
    regularization.
    """

    __slots__ = (
        "_anchor",
        "_c2",
        "_failed_below",
        "_floor",
        "_g",
        "_h",
        "_half_dev",
        "_hi",
        "_i",
        "_jphi",
        "_jxb",
        "_jxx",
        "_jxy",
        "_lo",
        "_m",
        "_n",
        "_noise_var",
        "_noise_w",
        "_nsettled",
        "_null_m_s",
        "_nv_before",
        "_p1_v",
        "_p1_y",
        "_pend",
        "_pend_j",
        "_prev",
        "_since_jump",
        "_snr",
        "_stale",
        "_t",
        "_tp_before",
        "_ts",
        "_ts_ring",
        "_vs",
        "_ys",
        "at_rest",
        "creep",
        "creep_integral_m",
        "product_fresh",
        "product_settled",
        "product_updated",
        "spool_integral_m",
        "still_samples",
        "theta_prod",
    )

    def __init__(
        self, plant: PlantParams, ts_s: float, scale_m: float, tuning: ControlTuning | None = None
    ) -> None:
        t = tuning if tuning is not None else ControlTuning()
        self._half_dev = 0.5 * t.flow_gain_min_deviation
        self._failed_below = t.sensor_failed_below
        self._lo, self._hi = t.k_dft_limits[0], t.k_dft_limits[1]
        self._h = 0.5 * ts_s * plant.velocity_gain_1_s
        self._m = t.increment_window
        self._g = per_sample_gain(t.nlms_gain_per_ms, ts_s)
        inc = plant.velocity_gain_1_s * scale_m * self._m * ts_s
        self._c2 = (t.nlms_c_fraction * inc) ** 2
        self._floor = t.flow_gain_excitation * inc
        self._snr = t.excitation_snr
        self._noise_w = t.noise_weight
        self._ts = ts_s
        #: the piston's velocity with the spool at null (:mod:`.creep`)
        self.creep = CreepEstimator(plant.velocity_gain_1_s * plant.spool_stroke_m, t)
        self._null_m_s = self.creep.null_m_s
        self.reset()

    @property
    def reading_noise_m(self) -> float:
        """The position reading's one-sample noise σ̂ (m), from its one-sample increments the
        product does not explain (their variance is 2σ̂²)."""
        return math.sqrt(0.5 * self._noise_var)

    def reset(self) -> None:
        """θ_prod = 1, empty window, no creep."""
        self.theta_prod = 1.0
        self._ys = [0.0] * self._m
        self._vs = [0.0] * self._m
        self._ts_ring = [0.0] * self._m
        self._p1_y, self._p1_v = math.nan, 0.0  # the last call's position and spool integral (m)
        #: the variance of one sample's position increment about what the spool explains (m²)
        self._noise_var = self._nv_before = 0.0
        self._tp_before = 1.0  # θ_prod before the last call
        self._t = 0.0  # time the product has spanned (s)
        self._i = self._n = 0
        self.creep.reset()
        self._pend: tuple[float, float, float, float] | None = None  # the last increment
        self._pend_j: tuple[float, float, float] | None = None  # the last increment of the joint fit
        self._since_jump = self._m + 1  # samples since the reading last jumped
        self.restart_fit()
        #: samples since the reading last moved by more than the excitation gate over an
        #: increment (a stuck or failed sensor never does)
        self.still_samples = 0
        #: the spool integral moved less than the excitation gate over the last increment: no
        #: flow the model knows of (whatever the reading's noise does to :attr:`product_fresh`)
        self.at_rest = True
        #: the creep's share of the piston's travel, ∫ĉ/θ_prod dt (m at the nominal flow gain,
        #: beside :attr:`spool_integral_m`)
        self.creep_integral_m = 0.0
        #: the running integral K_c·∫y_v of the measured spool (m of piston travel at the nominal
        #: flow gain), as of the last :meth:`product` call
        self.spool_integral_m = self._prev = 0.0
        self._stale = 0  # updates since the product estimate last had an excited increment
        #: θ_prod had an excited increment within the last M updates
        self.product_fresh = True
        #: θ_prod took an excited increment on the last :meth:`product` call
        self.product_updated = True
        self._anchor = math.inf  # θ_prod where the present run of settled updates began
        self._nsettled = 0  # excited updates since, each within min_deviation/2 of it
        #: the last M excited increments left θ_prod within ``min_deviation``/2 of where they
        #: began (a span across a sensor jump, or a gain still converging, is not settled)
        self.product_settled = False

    @property
    def increment_window(self) -> int:
        """M, the samples an increment spans."""
        return self._m

    def note_jump(self) -> None:
        """The reading jumped on the last sample: its increment is no noise and the increments
        spanning it are no gain (the noise estimate and θ_prod are taken back to before it, the
        next M − 1 increments do not move θ_prod, and θ_prod is stale until they do and settles
        afresh), they teach no creep, the joint fit closes and the fit since the jump starts."""
        self._since_jump = 0
        self._noise_var = self._nv_before  # a jump is no noise
        self.theta_prod = self._tp_before  # nor is an increment spanning it a gain
        self._anchor, self._nsettled = math.inf, 0  # what settled before it is no verdict after
        self.product_settled = False
        # and the product before it is no evidence of the reading after it
        self._stale = self._m + 1
        self.product_fresh = self.product_updated = False
        self.restart_fit()
        self.creep.close_joint()

    def restart_fit(self) -> None:
        """Start :attr:`since_jump_fit` afresh from this sample (a jump, a change seen at rest)."""
        #: Σφ², Σy·φ and Σφ·φ_next (consecutive ones) over the excited, non-overlapping
        #: increments since the last jump (m²), and the φ of the last one taken (0: none)
        self._jxx = self._jxy = self._jxb = self._jphi = 0.0

    @property
    def since_jump_fit(self) -> tuple[float, float]:
        """The gain the reading has shown since its last jump (or :meth:`restart_fit`): the
        least-squares ratio r = Σy·φ/Σφ² of the excited, non-overlapping M-sample increments
        taken since, none spanning the jump, and its standard error under the reading's noise
        (1). Consecutive increments share an endpoint, so their noises are correlated
        (covariance −σ²; each has variance 2σ²): var r = 2σ²·(Σφ² − Σφ_i·φ_i+1)/(Σφ²)², which
        on a steady motion falls as 1/N² — the noise of the two ends of the whole travel.
        (NaN, inf) before the first such increment."""
        a = self._jxx
        if a <= 0.0:
            return math.nan, math.inf
        return self._jxy / a, math.sqrt(self._noise_var * max(a - self._jxb, 0.0)) / a

    def confirms(self, theta: float) -> bool:
        """θ_prod is settled within ``flow_gain_min_deviation``/2 of ``theta``: the increments
        say the reading is ``theta`` times the piston's travel at the nominal flow gain."""
        return self.product_settled and abs(self.theta_prod - theta) < self._half_dev

    def product(self, position_m: float, spool_m: float, samples: int = 1, excited: bool = True) -> float:
        """One fresh sample: the position reading and the spool LVDT (m); ``samples``: sensor
        samples since the previous call (the spool taken linear over those not seen), so that
        both sides of an increment span the same time; ``excited`` False (the spool at its
        stop): the increment is not used. Returns θ_prod.

        Attributes are read once into locals (this runs on every fresh sample); the arithmetic
        is the same expression for expression."""
        si = self.spool_integral_m + self._h * samples * (spool_m + self._prev)
        self.spool_integral_m = si
        dt = samples * self._ts
        t_now = self._t + dt
        self._t = t_now
        creep = self.creep
        rate = creep.rate_m_s
        tp = self._tp_before = self.theta_prod
        if rate and tp >= self._failed_below:
            self.creep_integral_m += dt * rate / tp
        self._prev = spool_m
        y1 = self._p1_y
        nv = self._noise_var
        if samples == 1 and y1 == y1:  # one sample's increment: the reading's noise
            r = position_m - y1 - tp * (si - self._p1_v) - rate * dt
            self._nv_before = nv
            nv += self._noise_w * (r * r - nv)
            self._noise_var = nv
        self._p1_y, self._p1_v = position_m, si
        i, m = self._i, self._m
        ys, vs, ring = self._ys, self._vs, self._ts_ring
        y = position_m - ys[i]
        phi = si - vs[i]
        tau = t_now - ring[i]
        ys[i], vs[i], ring[i] = position_m, si, t_now
        self._i = (i + 1) % m
        n = self._n = self._n + 1
        stale = self._stale + 1
        gate = self._floor
        self.still_samples = 0 if abs(y) > gate else self.still_samples + samples
        self.at_rest = abs(phi) <= gate
        # the creep learns from the last increment now that a jump inside it would be known
        since = self._since_jump = self._since_jump + 1
        pend = self._pend
        if pend is not None and since > m:
            creep.update(*pend)
        # only an increment with the spool near null teaches the creep (CreepEstimator.update)
        if n > m and excited and abs(phi) <= self._null_m_s * tau:
            self._pend = (y, phi, tau, tp)
        else:
            self._pend = None
        if creep.joint_open:  # the joint fit, on every M-th increment (they do not overlap)
            pj = self._pend_j
            if pj is not None and since > m:
                creep.joint(pj[0], pj[1], pj[2], nv)
            self._pend_j = (y, phi, tau) if n > m and excited and n % m == 0 else None
        y -= creep.rate_m_s * tau  # the creep's share of the increment is no gain
        floor = self._snr * math.sqrt(nv)
        if not floor > gate:  # max(gate, floor), written out
            floor = gate
        if n > m and abs(phi) > floor and excited and since > m:  # none spans a jump
            if n % m == 0:
                self._jxx += phi * phi
                self._jxy += y * phi
                self._jxb += phi * self._jphi
                self._jphi = phi
            stale = 0
            t = tp
            t += self._g * (y - t * phi) * phi / (self._c2 + phi * phi)
            lo, hi = self._lo, self._hi
            if lo > t:  # min(max(t, lo), hi), written out
                t = lo
            if hi < t:
                t = hi
            self.theta_prod = t
            if abs(t - self._anchor) < self._half_dev:
                self._nsettled += 1
                self.product_settled = self._nsettled >= m
            else:  # moved off: a new run of updates starts here
                self._anchor, self._nsettled = t, 0
                self.product_settled = False
        if n % m == 0 and stale:  # this M-th increment was not taken: the next is no neighbour
            self._jphi = 0.0
        self._stale = stale
        self.product_fresh = stale <= m
        self.product_updated = stale == 0
        return self.theta_prod
