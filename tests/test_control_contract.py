"""The one controller contract (control/base.py ``Controller``, an ABC): every registered mode
is one, a law must implement configure/reset/step, and the defaults of the rest behave."""

from __future__ import annotations

import os
import subprocess
import sys

import pytest
from _proc import ROOT

from ehpss_hil.control.base import Controller, ControllerStatus, Measurement, ValveCommand
from ehpss_hil.control.registry import MODES, REGISTRY, make_controller
from ehpss_hil.errors import ModelError
from ehpss_hil.physics import load_params
from ehpss_hil.physics.params import Params

PARAMS = load_params()
TS_S = 1e-3


@pytest.mark.parametrize("mode", MODES)
def test_every_registered_mode_is_a_controller_and_runs(mode: str) -> None:
    ctrl = make_controller(mode, PARAMS, TS_S)
    assert isinstance(ctrl, Controller) and issubclass(REGISTRY[mode].cls, Controller)
    assert ctrl.mode == mode
    meas = Measurement(position_m=2e-4, spool_m=1e-5, reference_m=5e-4, samples=1)
    ctrl.observe(meas)
    cmd = ctrl.step(meas)
    assert cmd.enable and 0.0 < cmd.current_a < 1.0  # x below x_d: a positive current
    st = ctrl.status()
    assert st.mode == mode and set(st.index) == set(ctrl.index_slots) == set(st.theta)
    spool, pos, k_loe, k_dft = ctrl.probe()
    assert (st.k_loe_hat, st.k_dft_hat) == (k_loe, k_dft)
    assert (spool >= 0) == ("spool" in st.active_model) and (pos >= 0) == ("position" in st.active_model)
    ctrl.reset()
    assert ctrl.step(meas).current_a == pytest.approx(cmd.current_a, rel=1e-12)  # reset: as new


@pytest.mark.parametrize("mode", MODES)
def test_the_sample_record_is_the_probe_then_the_index(mode: str) -> None:
    """What the simulator records per sample (``sample_record``, mmac builds its own) is the
    probe then J of every slot, as the two probes give them, also after the models moved."""
    ctrl = make_controller(mode, PARAMS, TS_S)
    for k in range(300):
        x = 2e-4 * (1.0 - 0.99**k)
        ctrl.step(Measurement(position_m=x, spool_m=1e-5 * 0.99**k, reference_m=5e-4, samples=1))
    rec = ctrl.sample_record()
    assert rec == (*ctrl.probe(), *ctrl.index_values())
    assert len(rec) == 4 + len(ctrl.index_slots)
    if mode == "mmac":  # the mode that builds it itself: every model scored
        assert all(v > 0.0 for v in rec[4:])


def test_an_unknown_mode_is_one_model_error() -> None:
    with pytest.raises(ModelError, match="unknown controller mode 'pid'; choose one of nrc, smac"):
        make_controller("pid", PARAMS, TS_S)


class Gain(Controller):
    """The smallest law: a proportional gain (A/m), no banks."""

    mode = "gain"

    def configure(self, params: Params, ts_s: float) -> None:
        self.k = 10.0

    def reset(self) -> None:
        self.steps = 0

    def step(self, meas: Measurement) -> ValveCommand:
        self.steps += 1
        return ValveCommand(self.k * (meas.reference_m - meas.position_m))


def test_a_law_without_configure_reset_or_step_cannot_be_made() -> None:
    class NoStep(Controller):
        def configure(self, params: Params, ts_s: float) -> None: ...

        def reset(self) -> None: ...

    with pytest.raises(TypeError, match=r"abstract method.*'?step"):
        NoStep()  # type: ignore[abstract]


def test_the_defaults_of_a_law_without_banks() -> None:
    law = Gain()
    law.configure(PARAMS, TS_S)
    law.reset()
    meas = Measurement(position_m=1e-3, reference_m=3e-3)
    law.observe(meas)  # ignored: no step counted, nothing returned
    assert law.steps == 0
    assert law.step(meas).current_a == pytest.approx(0.02)
    assert law.probe() == (-1, -1, 1.0, 1.0)
    assert (law.index_values(), law.theta_values(), law.switch_count()) == ([], [], 0)
    assert (law.fallback_reason(), law.fallback_count(), law.nominal) == (0, 0, False)
    assert law.status() == ControllerStatus(mode="gain")


def test_status_is_built_from_the_probes() -> None:
    class Banked(Gain):
        index_slots = (4, 7)
        nominal = True

        def probe(self) -> tuple[int, int, float, float]:
            return (-1, 7, 0.8, 0.5)

        def index_values(self) -> list[float]:
            return [0.25, 0.125]

        def theta_values(self) -> list[float]:
            return [1.0, 0.5]

        def switch_count(self) -> int:
            return 3

        def fallback_reason(self) -> int:
            return 2

    st = Banked().status()
    assert st == ControllerStatus(
        mode="gain",
        active_model={"position": 7},
        k_loe_hat=0.8,
        k_dft_hat=0.5,
        index={4: 0.25, 7: 0.125},
        theta={4: 1.0, 7: 0.5},
        switches=3,
        fallback=True,
        fallback_reason=2,
        fallbacks=0,
    )


def not_a_law(mode: str, params: Params, ts_s: float, cfg: object) -> object:
    """A ``--controller-factory`` that returns something else than a Controller."""
    return object()


def test_the_daemon_refuses_a_factory_that_returns_no_controller() -> None:
    r = subprocess.run(
        [
            sys.executable,
            "-m",
            "ehpss_hil.cli",
            "controller",
            "-c",
            "configs/controller.yaml",
            "--controller-factory",
            "test_control_contract:not_a_law",
        ],
        cwd=ROOT,
        env={**os.environ, "PYTHONPATH": str(ROOT / "tests")},
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 2, r.stderr
    lines = r.stderr.strip().splitlines()
    assert (
        len(lines) == 1
        and "--controller-factory" in lines[0]
        and "returned a object, not a Controller" in lines[0]
    )
