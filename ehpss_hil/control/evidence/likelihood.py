"""The pressure test's evidence window and its likelihood ratio (docs/control.md §5).

The window holds exponentially weighted sums of the unit-gain load-pressure prediction ``u``
(Pa per unit gain) and the measured load pressure ``P_L`` (Pa): ``Σw·u²``, ``Σw·u·P_L``,
``Σw·P_L²`` and ``Σw``. A hypothesis says ``P_L = g·u``; its residual energy for the gain ``ĝ``
that fits best within a band around ``g`` follows from the sums alone, so the window needs no
samples kept and a hypothesis' gain may be chosen after the evidence was taken.
"""

from __future__ import annotations


class PressureWindow:
    """Exponentially weighted sums of ``u`` and ``P_L`` (forgetting factor ``decay`` per sample)
    and the generalized likelihood ratio of two gains on them."""

    __slots__ = ("decay", "spp", "sup", "suu", "w")

    def __init__(self, decay: float) -> None:
        #: the weight a sample loses per sample (exp(−T_s/window))
        self.decay = decay
        self.empty()

    def empty(self) -> None:
        """No evidence."""
        self.suu = self.sup = self.spp = self.w = 0.0

    def add(self, u: float, p_l: float) -> None:
        """One sample: the prediction at unit gain ``u`` and the measured ``p_l`` (Pa)."""
        d = self.decay
        self.suu = d * self.suu + u * u
        self.sup = d * self.sup + u * p_l
        self.spp = d * self.spp + p_l * p_l
        self.w = d * self.w + 1.0

    def fit(self, lo: float, hi: float, band: float) -> float:
        """Σw·(P_L − ĝ·u)² (Pa²) for the ĝ within [lo·(1 − band), hi·(1 + band)] that fits best."""
        g = lo
        if (band > 0.0 or hi > lo) and self.suu > 0.0:
            g = min(max(self.sup / self.suu, lo * (1.0 - band)), hi * (1.0 + band))
        return self.spp - 2.0 * g * self.sup + g * g * self.suu

    def llr(self, g_d: float, g_q: float, spread: float, band: float) -> float:
        """Λ = (E_D − E_Q)/(2σ̂²) for ``P_L = g·u`` with g = ``g_d`` against g = ``g_q`` ±
        ``spread``, each gain known within the relative ``band`` (each hypothesis takes the gain
        within its interval that fits best: 0 where the fitted gain lies in both);
        σ̂² = min(E_D, E_Q)/Σw. 0 while nothing is explained better."""
        e_d = self.fit(g_d, g_d, band)
        e_q = self.fit(g_q - spread, g_q + spread, band)
        var = min(e_d, e_q) / self.w
        return (e_d - e_q) / (2.0 * var) if var > 0.0 else 0.0
