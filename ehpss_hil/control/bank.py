"""Model banks with the corrected eq 36 performance index.

A bank holds fixed models, a free-running adaptive model (FRA) and a reinitialized adaptive
model (RIA), in that order. For every model k, with the residual normalized by the channel's
nominal amplitude S (``ε_k = (y − ŷ_k)/S``, dimensionless):

    I_k ← e^{−λTs}·I_k + Ts·ε_k²          (eq 36's integral with the corrected exponent −λ(t − τ))
    J_k = a1·ε_k² + a2·I_k

The banks also track ``w = Σ Ts·e^{−λ·j·Ts}`` so that ``min_k I_k / w`` is the mean-square residual
of the best model over the memory window: the channel's noise floor (docs/design.md §5).
"""

from __future__ import annotations

import math

from .estimator import Nlms
from .tuning import ControlTuning


class _IndexBase:
    """Shared index state: per-model I_k and J_k lists, the window weight w."""

    __slots__ = (
        "_a1",
        "_a2",
        "_decay",
        "_index_consts",
        "_ts",
        "fra",
        "inv_scale",
        "j",
        "mem",
        "n",
        "n_fixed",
        "ria",
        "w",
    )

    def __init__(self, n: int, n_fixed: int, tuning: ControlTuning, ts_s: float, scale: float) -> None:
        self.n = n
        self.n_fixed = n_fixed
        self.fra = n_fixed
        self.ria = n_fixed + 1
        self._decay = math.exp(-tuning.forgetting_1_s * ts_s)
        self._ts = ts_s
        self._a1 = tuning.index_a1
        self._a2 = tuning.index_a2
        self.inv_scale = 1.0 / scale
        #: (e^{−λTs}, Ts, a1, a2, 1/S): what a sample's scoring reads, in one tuple (one unpack)
        self._index_consts = (self._decay, ts_s, self._a1, self._a2, self.inv_scale)
        self.mem = [0.0] * n
        self.j = [0.0] * n
        self.w = 0.0

    def reset_index(self) -> None:
        """Forget all index memory."""
        self.mem = [0.0] * self.n
        self.j = [0.0] * self.n
        self.w = 0.0

    def _score(self, residuals: list[float]) -> None:
        d, ts, a1, a2, s = self._decay, self._ts, self._a1, self._a2, self.inv_scale
        mem, jj = self.mem, self.j
        for i, r in enumerate(residuals):
            e2 = (r * s) ** 2
            m = d * mem[i] + ts * e2
            mem[i] = m
            jj[i] = a1 * e2 + a2 * m
        self.w = d * self.w + ts

    def noise_floor(self) -> float:
        """Mean-square normalized residual of the best model over the index memory."""
        return min(self.mem) / self.w if self.w > 0.0 else 0.0


class ScalarBank(_IndexBase):
    """One channel ``y = θ·φ``: fixed θ values, then FRA, then RIA (NLMS from the nominal 1.0)."""

    __slots__ = (
        "_adapt_floor",
        "_nlms",
        "fixed",
        "fra_est",
        "ria_est",
        "theta",
    )

    def __init__(
        self,
        fixed: tuple[float, ...],
        tuning: ControlTuning,
        ts_s: float,
        scale: float,
        gain: float,
        limits: tuple[float, float],
        theta0: float = 1.0,
    ) -> None:
        super().__init__(len(fixed) + 2, len(fixed), tuning, ts_s, scale)
        c = (tuning.nlms_c_fraction * scale) ** 2
        self.fixed = tuple(float(f) for f in fixed)
        self.fra_est = Nlms(theta0, gain, c, *limits)
        self.ria_est = Nlms(theta0, gain, c, *limits)
        self.theta = [*self.fixed, theta0, theta0]
        self._adapt_floor = tuning.excitation_floor
        #: the NLMS step's (gain, c, lo, hi), the same for FRA and RIA (:meth:`update` writes
        #: their step out)
        self._nlms = (gain, c, *limits)

    def reset(self) -> None:
        """Estimators to θ0, index memory cleared."""
        self.fra_est.reset()
        self.ria_est.reset()
        self.theta = [*self.fixed, self.fra_est.theta, self.ria_est.theta]
        self.reset_index()

    def update(self, y: float, phi: float) -> None:
        """Score every model on the sample (a priori residuals), then adapt FRA and RIA, unless
        the regressor is below the excitation floor (|φ|/S < ``excitation_floor``: no evidence
        of θ, only of noise and of offsets the proportional model does not have).

        Written out by hand (no per-model calls): this runs twice per cycle in ``mmac``.
        """
        th, mem, jj = self.theta, self.mem, self.j
        d, ts, a1, a2, s = self._index_consts
        ys, ps = y * s, phi * s
        i = 0
        for t in th:  # in place, one index counted by hand: faster than enumerate or new lists
            r = ys - t * ps
            e2 = r * r
            m = d * mem[i] + ts * e2
            mem[i] = m
            jj[i] = a1 * e2 + a2 * m
            i += 1
        self.w = d * self.w + ts
        floor = self._adapt_floor
        if -floor < ps < floor:  # not excited: no evidence of θ
            return
        g, c, lo, hi = self._nlms
        k = g * phi / (c + phi * phi)
        t = self.fra_est.theta
        t += k * (y - t * phi)
        t = lo if t < lo else hi if t > hi else t
        self.fra_est.theta = th[self.fra] = t
        t = self.ria_est.theta
        t += k * (y - t * phi)
        t = lo if t < lo else hi if t > hi else t
        self.ria_est.theta = th[self.ria] = t

    def separation(self, a: int, b: int) -> float:
        """|θ_a − θ_b|."""
        return abs(self.theta[a] - self.theta[b])

    def seed_ria(self, theta: float) -> None:
        """RIA restarts at ``theta`` (clipped to its limits), index memory of the best model."""
        ria = self.ria_est
        t = min(max(theta, ria._lo), ria._hi)
        ria.theta = self.theta[self.ria] = t
        best = self.mem.index(min(self.mem))
        self.mem[self.ria] = self.mem[best]
        self.j[self.ria] = self.j[best]

    def reinit_ria(self, source: int) -> None:
        """RIA takes model ``source``'s θ and index memory (Narendra's reinitialization)."""
        self.ria_est.theta = self.theta[source]
        self.theta[self.ria] = self.theta[source]
        self.mem[self.ria] = self.mem[source]
        self.j[self.ria] = self.j[source]


class JointBank(_IndexBase):
    """The paper's joint bank on ``y = θ_L·θ_D·φ``: fixed (θ_L, θ_D) pairs, then FRA and RIA.

    The adaptive models adapt the actuator factor θ_L (NLMS on the regressor θ_D·φ) with their
    θ_D held: 1 for the FRA, the θ_D of the fixed model the RIA was last reinitialized to.
    """

    __slots__ = (
        "_ria_d",
        "fixed",
        "fra_est",
        "pairs",
        "ria_est",
    )

    def __init__(
        self,
        fixed: tuple[tuple[float, float], ...],
        tuning: ControlTuning,
        ts_s: float,
        scale: float,
        gain: float,
    ) -> None:
        super().__init__(len(fixed) + 2, len(fixed), tuning, ts_s, scale)
        c = (tuning.nlms_c_fraction * scale) ** 2
        lim = (tuning.k_loe_limits[0], tuning.k_loe_limits[1])
        self.fixed = tuple((float(a), float(b)) for a, b in fixed)
        self.fra_est = Nlms(1.0, gain, c, *lim)
        self.ria_est = Nlms(1.0, gain, c, *lim)
        self._ria_d = 1.0
        self.pairs = [*self.fixed, (1.0, 1.0), (1.0, 1.0)]

    def reset(self) -> None:
        """Estimators to (1, 1), index memory cleared."""
        self.fra_est.reset()
        self.ria_est.reset()
        self._ria_d = 1.0
        self.pairs = [*self.fixed, (1.0, 1.0), (1.0, 1.0)]
        self.reset_index()

    def update(self, y: float, phi: float) -> None:
        """Score every model (a priori residuals), then adapt FRA and RIA."""
        res = [y - a * b * phi for a, b in self.pairs[: self.n_fixed]]
        res.append(self.fra_est.update(y, phi))
        res.append(self.ria_est.update(y, self._ria_d * phi))
        self.pairs[self.fra] = (self.fra_est.theta, 1.0)
        self.pairs[self.ria] = (self.ria_est.theta, self._ria_d)
        self._score(res)

    def separation(self, a: int, b: int) -> float:
        """max(|Δθ_L|, |Δθ_D|) between models a and b."""
        (la, da), (lb, db) = self.pairs[a], self.pairs[b]
        return max(abs(la - lb), abs(da - db))

    def reinit_ria(self, source: int) -> None:
        """RIA takes model ``source``'s (θ_L, θ_D) and index memory."""
        tl, td = self.pairs[source]
        self.ria_est.theta = tl
        self._ria_d = td
        self.pairs[self.ria] = (tl, td)
        self.mem[self.ria] = self.mem[source]
        self.j[self.ria] = self.j[source]
