"""Supervisor: hysteresis, dwell, warm-up, θ separation, excitation, RIA reinit, guards."""

from __future__ import annotations

from dataclasses import replace

import pytest

from ehpss_hil.control.bank import ScalarBank
from ehpss_hil.control.base import Measurement
from ehpss_hil.control.registry import make_controller
from ehpss_hil.control.supervisor import Supervisor
from ehpss_hil.control.tuning import ControlTuning
from ehpss_hil.physics.load import load_params

TS = 1e-3


class FakeBank:
    """A bank whose J values the test sets directly."""

    def __init__(self, thetas: list[float], n_fixed: int = 2) -> None:
        self.theta = thetas
        self.n = len(thetas)
        self.n_fixed = n_fixed
        self.j = [1.0] * self.n
        self.reinit_from: list[int] = []

    def noise_floor(self) -> float:
        return 0.0

    def separation(self, a: int, b: int) -> float:
        return abs(self.theta[a] - self.theta[b])

    def reinit_ria(self, source: int) -> None:
        self.reinit_from.append(source)


def _sup(
    bank: FakeBank,
    *,
    warmup_s: float = 0.0,
    switch_confirm_s: float = 0.0,
    dwell_s: float = ControlTuning().dwell_s,
) -> Supervisor:
    t = replace(ControlTuning(), warmup_s=warmup_s, switch_confirm_s=switch_confirm_s, dwell_s=dwell_s)
    return Supervisor(bank, t, TS)


def test_a_switch_needs_its_condition_to_hold_for_the_confirmation_time() -> None:
    """One sample of a better J (a noise spike) never switches; the same candidate better for
    switch_confirm_s in a row does, and a different candidate restarts the count."""
    bank = FakeBank([1.0, 0.5, 0.7, 0.7])
    sup = _sup(bank, switch_confirm_s=0.004)
    good, other, bad = [1.0, 0.1, 2.0, 2.0], [1.0, 2.0, 0.1, 2.0], [1.0, 2.0, 2.0, 2.0]
    for seq in ([good, bad] * 5, [good, good, good, other, good, bad]):
        for j in seq:
            bank.j = j
            assert sup.update(1.0) == 0
    bank.j = good
    for _ in range(3):
        assert sup.update(1.0) == 0
    assert sup.update(1.0) == 1 and sup.switches == 1


def test_hysteresis_needs_relative_and_absolute_margin() -> None:
    bank = FakeBank([1.0, 0.5, 0.7, 0.7])
    sup = _sup(bank)
    margin = (1 + 1 / 10) * 0.005**2
    bank.j = [1.0, 0.8 - margin + 1e-9, 2.0, 2.0]  # just not good enough
    assert sup.update(1.0) == 0
    bank.j = [1.0, 0.8 - margin - 1e-9, 2.0, 2.0]
    assert sup.update(1.0) == 1 and sup.switches == 1


def test_dwell_blocks_a_second_switch() -> None:
    bank = FakeBank([1.0, 0.5, 0.7, 0.7])
    sup = _sup(bank, dwell_s=0.005)
    bank.j = [1.0, 0.1, 2.0, 2.0]
    assert sup.update(1.0) == 1
    bank.j = [0.01, 1.0, 2.0, 2.0]
    for _ in range(4):  # 4 samples < 5 ms dwell
        assert sup.update(1.0) == 1
    assert sup.update(1.0) == 0


def test_warmup_blocks_switching() -> None:
    bank = FakeBank([1.0, 0.5, 0.7, 0.7])
    sup = _sup(bank, warmup_s=0.1)
    bank.j = [1.0, 0.1, 2.0, 2.0]
    for _ in range(99):
        assert sup.update(1.0) == 0
    assert sup.update(1.0) == 1


def test_no_switch_between_twins_or_without_excitation() -> None:
    bank = FakeBank([1.0, 0.5, 1.01, 0.7])
    sup = _sup(bank)
    bank.j = [1.0, 2.0, 0.01, 2.0]  # FRA much better but θ within 0.02 of the active
    assert sup.update(1.0) == 0
    bank.j = [1.0, 0.01, 2.0, 2.0]
    assert sup.update(0.01) == 0  # |φ|/S below the excitation floor
    assert sup.update(1.0) == 1


def test_switch_to_fixed_reinitializes_ria() -> None:
    bank = ScalarBank((1.0, 0.5), ControlTuning(), TS, 1.0, 0.2, (0.05, 1.5))
    sup = Supervisor(bank, replace(ControlTuning(), warmup_s=0.0), TS)
    for k in range(30):
        phi = 1.0 if k % 2 else -1.0
        bank.update(0.5 * phi, phi)
        sup.update(1.0)
    assert sup.active in (1, bank.fra, bank.ria)
    # force the fixed 0.5 model: its θ and index memory go to the RIA
    bank.ria_est.theta = 1.3
    sup._switch(1)
    assert bank.theta[bank.ria] == 0.5 and bank.ria_est.theta == 0.5
    assert bank.mem[bank.ria] == bank.mem[1]


def test_guard_trips_and_releases() -> None:
    bank = FakeBank([1.0, 0.5, 0.7, 0.7])
    sup = Supervisor(bank, ControlTuning(), TS, guard_epsilon=0.4)
    jmax = (1 + 1 / 10) * 0.16
    bank.j = [jmax * 1.01] * 4
    sup.update(1.0)
    assert sup.guarded
    bank.j = [jmax * 0.3] * 4  # below J_max but above J_max/4: still guarded
    sup.update(1.0)
    assert sup.guarded
    bank.j = [jmax * 0.2] * 4
    sup.update(1.0)
    assert not sup.guarded


def test_spool_guard_falls_back_to_nominal_loe() -> None:
    """Spool readings no model explains (uncorrelated with the predicted spool) → k̂_LOE = 1."""
    ctrl = make_controller("mmac", load_params(), TS)
    meas = Measurement()
    for k in range(400):
        meas.coil_current_a = 1e-4 * (1 if (k // 50) % 2 else -1)
        meas.spool_m = 3e-3 * (1 if (k // 7) % 2 else -1)  # garbage
        meas.position_m = 0.0
        ctrl.step(meas)
    assert ctrl.spool_sup.guarded  # type: ignore[attr-defined]
    assert ctrl.k_loe_hat == 1.0


def test_sustained_guard_ignores_short_transients() -> None:
    bank = FakeBank([1.0, 0.5, 0.7, 0.7])
    sup = Supervisor(bank, ControlTuning(), TS, guard_epsilon=0.4, sustained_guard=True)
    bank.j = [100.0] * 4  # huge instantaneous J, but no memory (noise floor 0)
    sup.update(1.0)
    assert not sup.guarded


@pytest.mark.parametrize("mode", ["mmac", "mmac-paper"])
def test_reset_returns_to_nominal(mode: str) -> None:
    ctrl = make_controller(mode, load_params(), TS)
    ctrl.k_loe_hat = 0.3
    ctrl.reset()
    assert ctrl.k_loe_hat == 1.0 and ctrl.switch_count() == 0
