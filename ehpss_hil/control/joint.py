"""The paper's sensing (the position alone): ``smac`` and ``mmac-paper`` (a joint model).

The regression is over a window of M samples, ``y = y_s[k] − y_s[k−M]`` against
``φ = K_c·∫_{k−M}^{k} v dt``, i.e. ``y = k_LOE·k_DFT·φ``: only the product is identifiable, so a
joint (θ_L, θ_D) model cannot tell a 50 % LOE from a 0.5 drift (docs/design.md §4). ``mmac-paper``
has the fixed pairs nominal, LOE 50 %, drift 0.5 plus FRA and RIA, whose adaptive law (the paper's
actuator parametrization) adapts θ_L with θ_D held (FRA: 1; RIA: the θ_D of the fixed model it was
reinitialized to); ``smac`` has one adaptive model, θ_L with θ_D = 1. Their x̂ integrates θ̂_L·v
(no spool sensor in this sensing).
"""

from __future__ import annotations

from .bank import JointBank
from .base import Measurement, NominalMotion, ValveCommand
from .controllers import JOINT_SLOT0, SMAC_SLOT, LoopBase
from .estimator import Nlms, per_sample_gain
from .supervisor import Supervisor
from .tuning import ControlTuning


class JointController(LoopBase):
    """``mmac-paper`` (joint bank + supervisor) or ``smac`` (one joint adaptive model)."""

    def __init__(self, tuning: ControlTuning, reference: NominalMotion | None, mode: str) -> None:
        super().__init__(tuning, reference)
        self.mode = mode

    def _build(self) -> None:
        t, ts = self.tuning, self.ts_s
        m = t.increment_window
        self._m = m
        k_c = self.params.plant.velocity_gain_1_s
        self._h = 0.5 * ts * k_c
        scale = self.scale_spool_m * k_c * ts * m
        self._inv_s = 1.0 / scale
        g = per_sample_gain(t.nlms_gain_per_ms, ts)
        if self.mode == "smac":
            c = (t.nlms_c_fraction * scale) ** 2
            self.est = Nlms(1.0, g, c, t.k_loe_limits[0], t.k_loe_limits[1])
            self.index_slots = (SMAC_SLOT,)
        else:
            fixed = ((1.0, 1.0), (0.5, 1.0), (1.0, 0.5))
            self.bank = JointBank(fixed, t, ts, scale, g)
            self.sup = Supervisor(self.bank, t, ts)
            self.index_slots = tuple(range(JOINT_SLOT0, JOINT_SLOT0 + 5))

    def _reset_mode(self) -> None:
        self._ys = [0.0] * self._m
        self._vs = [0.0] * self._m
        self._i = 0
        self._n = 0
        self._int_v = 0.0
        self._v_prev = 0.0
        if self.mode == "smac":
            self.est.reset()
        else:
            self.bank.reset()
            self.sup.reset()

    def step(self, meas: Measurement) -> ValveCommand:
        """Windowed increment regression, (bank + supervisor | single model), compensation."""
        if meas.fresh:
            self._echo = meas.coil_current_a
        v = self.valve.step(self._echo)
        self._int_v += self._h * (v + self._v_prev)
        self._v_prev = v
        self.xhat.integrate(self.k_loe_hat * v)
        i = self._i
        y = meas.position_m - self._ys[i]
        phi = self._int_v - self._vs[i]
        self._ys[i] = meas.position_m
        self._vs[i] = self._int_v
        self._i = (i + 1) % self._m
        self._n += 1
        if meas.fresh and self._n > self._m:
            self._adapt(y, phi)
        return self._close(meas)

    def _adapt(self, y: float, phi: float) -> None:
        if self.mode == "smac":
            self.est.update(y, phi)
            self.k_loe_hat = self.est.theta
        else:
            self.bank.update(y, phi)
            a = self.sup.update(abs(phi) * self._inv_s)
            self.k_loe_hat, self.k_dft_hat = self.bank.pairs[a]

    def index_values(self) -> list[float]:
        """J per model (smac: none is computed; reported as 0)."""
        return [0.0] if self.mode == "smac" else list(self.bank.j)

    def theta_values(self) -> list[float]:
        """θ_L·θ_D per model."""
        if self.mode == "smac":
            return [self.est.theta]
        return [a * b for a, b in self.bank.pairs]

    def probe(self) -> tuple[int, int, float, float]:
        """The joint slot is reported for both channels."""
        s = SMAC_SLOT if self.mode == "smac" else JOINT_SLOT0 + self.sup.active
        return (s, s, self.k_loe_hat, self.k_dft_hat)

    def switch_count(self) -> int:
        """Switches of the joint supervisor."""
        return 0 if self.mode == "smac" else self.sup.switches
