"""Cases 1–3 in lockstep through real CANopen frames: the controller as the CiA 408 master
(:class:`~ehpss_hil.protocol.cia408.codec.Cia408Codec`, its PDOs encoded on the emulator's side)
gives the native DBC's control metrics within the quantisation the CiA 408 scalings imply.

The tolerance comes from the position scalings, as in test_protocol_lockstep.py: a reading is
rounded to the encoder's measuring step q_c (0x6005.1: 100 nm) or the native LSB q_n (0.1 µm),
and the loop may settle anywhere in a quantisation cell, so one position seen through the two
profiles differs by up to q_c + q_n in sensor units, (q_c + q_n)/k in piston units at sensor gain
k. Every position metric (RMS, the pre-fault maximum, each event's peak) must agree within
(q_c + q_n)/k_min: 0.2 µm for case 1, 0.67 µm for case 2 (k_DFT 0.3), 0.25 µm for case 3
(k_DFT 0.8). The spool's 0.61 µm LSB (±16384 = the 10 mm stroke) and the set-point's 61 nA
(±16384 = 1 mA) are within the controller's needed resolution (1 µm, 10 µA: logical.py) and the
current echo is the master's own set-point of two cycles before, which is what the plant applied
with no command lost. Switch counts and recovery must be equal. Both runs use the master's
tuning (no flow-gain test: the valve reports no load pressure); the native default's metrics are
printed beside them.
"""

from __future__ import annotations

from pathlib import Path

import pytest

from ehpss_hil.config import load_controller_config
from ehpss_hil.protocol.cia408.codec import Cia408Codec
from ehpss_hil.report.metrics import RunMetrics, compute_metrics
from ehpss_hil.scenario import Scenario, load_scenario
from ehpss_hil.sim.lockstep import config_codec, run_scenario

ROOT = Path(__file__).resolve().parent.parent
CIA_CFG = str(ROOT / "configs" / "controller-cia408.yaml")
NATIVE_POSITION_LSB_M = 1e-7  # dbc/ehpss.dbc SENSOR_POS Position factor (m)
CASES = ("case1-loe", "case2-drift", "case3-combined")


def _k_min(sc: Scenario) -> float:
    gains = [ev.k_dft for ev in sc.events if ev.k_dft is not None and ev.k_dft > 0.0]
    return min([1.0, *gains])


def _peaks(m: RunMetrics) -> list[float]:
    return [m.rms_error_m, m.pre_fault_max_m, *(e.peak_error_m for e in m.events)]


def _um(m: RunMetrics) -> list[float]:
    return [round(x * 1e6, 3) for x in _peaks(m)]


@pytest.mark.parametrize("mode", ["nrc", "mmac"])
@pytest.mark.parametrize("case", CASES)
def test_cia408_master_gives_the_native_metrics(case: str, mode: str) -> None:
    sc = load_scenario(ROOT / "scenarios" / f"{case}.yaml")
    tuning = load_controller_config(CIA_CFG).tuning
    codec = config_codec(CIA_CFG)
    assert isinstance(codec, Cia408Codec)
    q_c = codec.scaling.step_m
    native = compute_metrics(run_scenario(sc, mode, tuning=tuning, transport="frames"))
    run = run_scenario(sc, mode, tuning=tuning, transport="frames", protocol_config=CIA_CFG)
    cia = compute_metrics(run)
    n = len(run.t_s)
    assert run.frame_counts["SYNC"] == n and run.frame_counts["OK"] == 3 * n  # 2 TPDOs + RPDO
    assert all(v == 0 for k, v in run.frame_counts.items() if k not in ("SYNC", "OK"))
    tol = (q_c + NATIVE_POSITION_LSB_M) / _k_min(sc)
    diffs = [abs(a - b) for a, b in zip(_peaks(native), _peaks(cia), strict=True)]
    default = compute_metrics(run_scenario(sc, mode, transport="frames")) if mode == "mmac" else native
    print(
        f"{case} {mode}: native {_um(native)} um, cia408 {_um(cia)} um (native default tuning "
        f"{_um(default)}); tolerance {tol * 1e6:.2f} um, max difference {max(diffs) * 1e6:.3f} um"
    )
    assert max(diffs) <= tol, (diffs, tol)
    assert cia.switches == native.switches
    assert [e.recovery_s for e in cia.events] == [e.recovery_s for e in native.events]


def test_the_protocol_config_brings_its_tuning() -> None:
    """Without a tuning of its own, a cia408 run takes the config's (mmac without its flow-gain
    test: the valve reports no load pressure, and a pressure of 0 would read as a k_Q loss)."""
    sc = load_scenario(ROOT / "scenarios" / "case2-drift.yaml")
    tuning = load_controller_config(CIA_CFG).tuning
    assert tuning.flow_gain_test is False
    implied = run_scenario(sc, "mmac", transport="frames", protocol_config=CIA_CFG)
    explicit = run_scenario(sc, "mmac", tuning=tuning, transport="frames", protocol_config=CIA_CFG)
    assert (implied.x_true_m == explicit.x_true_m).all() and (implied.current_a == explicit.current_a).all()
    assert compute_metrics(implied).rms_error_m < 2e-6


def test_the_position_from_the_valve_runs_alike(tmp_path: Path) -> None:
    """``position_source: valve`` (the valve's 0x2100 in its TPDO 2, 100 nm steps as the
    encoder's): the same run, sample for sample."""
    text = (ROOT / "configs" / "controller-cia408.yaml").read_text()
    text = text.replace("params: params.yaml", f"params: {ROOT / 'configs' / 'params.yaml'}")
    text = text.replace("dbc: ../dbc/ehpss.dbc", f"dbc: {ROOT / 'dbc' / 'ehpss.dbc'}")
    cfg = tmp_path / "valve-position.yaml"
    cfg.write_text(text.replace("position_source: encoder", "position_source: valve"))
    codec = config_codec(str(cfg))
    assert isinstance(codec, Cia408Codec) and codec.can_id("SENSOR_POS") == 0x2A0
    sc = load_scenario(ROOT / "scenarios" / "case1-loe.yaml")
    valve = run_scenario(sc, "mmac", transport="frames", protocol_config=str(cfg))
    encoder = run_scenario(sc, "mmac", transport="frames", protocol_config=CIA_CFG)
    assert valve.frame_counts["OK"] == 3 * len(valve.t_s) and valve.fresh.all()
    assert (valve.current_a == encoder.current_a).all() and (valve.x_true_m == encoder.x_true_m).all()
