"""PI law, predictors and the fault-free closed loop against the reference model."""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.control.adaptive import MmacController
from ehpss_hil.control.base import Measurement
from ehpss_hil.control.pi import PiLaw
from ehpss_hil.control.predictors import ModelPosition, ValvePredictor
from ehpss_hil.control.registry import MODES, make_controller
from ehpss_hil.control.sampleclock import bridge_bound_m, bridge_spool, span_currents
from ehpss_hil.control.tuning import ControlTuning
from ehpss_hil.errors import ModelError
from ehpss_hil.physics.faults import FaultState
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plant import PlantStepper
from ehpss_hil.report.result import SimResult
from ehpss_hil.scenario import Noise, load_scenario
from ehpss_hil.sim import run_scenario

PARAMS = load_params()
TS = 1e-3
MATCH_A = ControlTuning().wire_match_a
FAULT_FREE = load_scenario(PROJECT_ROOT / "scenarios" / "fault-free.yaml")


def test_pi_is_eq39() -> None:
    g = PARAMS.controller
    pi = PiLaw(g, TS)
    u0 = pi.step(1e-3, 0.0)  # reference enters as the mean of this and the last sample
    e0 = g.k_f * 0.5e-3
    assert u0 == pytest.approx(g.k_a * g.k_p * e0)
    assert pi.z == pytest.approx(TS * g.k_i * e0)
    u1 = pi.step(1e-3, 0.0)
    e1 = g.k_f * 1e-3
    assert u1 == pytest.approx(g.k_a * (g.k_p * e1 + g.k_i * TS * g.k_i * e0))


def test_valve_predictor_matches_plant_spool() -> None:
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_loe=0.4))
    pred = ValvePredictor(PARAMS.plant, TS)
    rng = np.random.default_rng(1)
    for i in rng.uniform(-0.001, 0.001, 300).tolist():  # within the stroke
        plant.step(i)
        v = pred.step(i)
        assert v == pytest.approx(plant.spool_commanded_m, rel=1e-9, abs=1e-15)
        assert 0.4 * v == pytest.approx(plant.spool_actual_m, rel=1e-9, abs=1e-15)


def test_spool_stops_at_its_stroke_in_plant_and_predictor() -> None:
    """A current that asks for more than the stroke: the plant's actual spool k_LOE·x_v stays on
    ±spool_stroke_m and the piston moves at K_c·stroke; the valve predictor with its stop at
    stroke/k_LOE gives the same commanded spool; back off the stop when the current reverses."""
    stroke = PARAMS.plant.spool_stroke_m
    plant = PlantStepper(PARAMS, TS)
    plant.set_faults(FaultState(k_loe=0.5))
    pred = ValvePredictor(PARAMS.plant, TS)
    pred.stop_m = stroke / 0.5
    for _ in range(50):
        plant.step(0.05)  # 0.05 A: 0.8 m of commanded spool unclipped
        v = pred.step(0.05)
    assert plant.spool_actual_m == pytest.approx(stroke, rel=1e-12)
    assert v == pytest.approx(plant.spool_commanded_m, rel=1e-12)
    x0 = plant.position_m
    for _ in range(10):
        plant.step(0.05)
    speed = (plant.position_m - x0) / (10 * TS)
    assert speed == pytest.approx(PARAMS.plant.velocity_gain_1_s * stroke, rel=1e-3)
    for _ in range(5):
        plant.step(-0.05)
        v = pred.step(-0.05)
    assert plant.spool_actual_m < stroke * 0.5
    assert v == pytest.approx(plant.spool_commanded_m, rel=1e-6)


def test_model_position_integrates_spool() -> None:
    xh = ModelPosition(PARAMS.plant, TS, anchor_rate_1_s=0.0)
    for _ in range(1000):
        xh.integrate(1e-3)
    kc = PARAMS.plant.velocity_gain_1_s
    assert xh.x == pytest.approx(kc * 1e-3 * (1.0 - 0.5e-3), rel=1e-9)  # trapezoid from rest
    xh.reset()
    xa = ModelPosition(PARAMS.plant, TS, anchor_rate_1_s=100.0)
    for _ in range(200):
        xa.integrate(0.0)
        xa.anchor(2e-3)
    assert xa.x == pytest.approx(2e-3, rel=1e-6)


def test_fault_free_loop_tracks_reference_model() -> None:
    """PI + plant (one-sample delay, quantized frames, noise) follows y_m to ≤ 3 µm RMS."""
    r = run_scenario(replace(FAULT_FREE, duration_s=2.0), "nrc", PARAMS)
    assert np.sqrt(np.mean(r.error_m**2)) <= 3e-6
    quiet = run_scenario(replace(FAULT_FREE, duration_s=2.0, noise=Noise()), "nrc", PARAMS)
    e = quiet.error_m[200:]  # after the start-up transient of the sine
    assert np.max(np.abs(e)) <= 0.5e-6


def test_factory_builds_every_mode_and_rejects_unknown() -> None:
    for mode in MODES:
        c = make_controller(mode, PARAMS, TS)
        assert c.mode == mode
        assert c.step(Measurement(reference_m=1e-4)).current_a != 0.0
        st = c.status()
        assert st.mode == mode
    with pytest.raises(ModelError):
        make_controller("pid", PARAMS, TS)
    with pytest.raises(ModelError):
        make_controller("nrc", PARAMS, 0.0)


def test_status_reports_documented_slots() -> None:
    st = make_controller("mmac", PARAMS, TS).status()
    assert st.active_model == {"spool": 0, "position": 4}
    assert sorted(st.index) == [0, 1, 2, 3, 4, 5, 6, 7, 8]
    assert st.theta[6] == 0.0 and st.theta[1] == 0.5
    assert sorted(make_controller("mmac-paper", PARAMS, TS).status().index) == [9, 10, 11, 12, 13]
    assert list(make_controller("smac", PARAMS, TS).status().index) == [14]


def test_oracle_uses_the_truth() -> None:
    c = make_controller("oracle", PARAMS, TS)
    c.set_truth(FaultState(k_loe=0.5, k_q=0.8, k_dft=0.1))  # type: ignore[attr-defined]
    assert c.k_loe_hat == pytest.approx(0.4)
    c.step(Measurement(position_m=5e-4, reference_m=1e-3))
    assert not c.sensor_trusted  # k_DFT below 0.15: model position instead of the sensor


def test_mmac_reanchors_x_hat_after_a_gap_and_only_then() -> None:
    """x̂ is dead-reckoned through cycles without data; the first trusted sample after the gap
    puts it on y_s/θ̂_D (and the position bank skips that sample), while an ordinary sample only
    nudges it at the anchor rate. Past the start-up warm-up in both cases."""
    c = make_controller("mmac", PARAMS, TS)
    assert isinstance(c, MmacController)
    m = Measurement()
    for _ in range(200):  # at rest, past the 0.1 s warm-up
        c.step(m)
    j_before = list(c.pos_bank.j)
    m.position_m = 20e-6  # the sensor disagrees with x̂ (0) by 20 µm
    c.step(m)
    assert 0.0 < c.xhat.x < 1e-6  # an ordinary sample: a nudge of Ts·2 s⁻¹
    m.fresh = False
    c.step(m)
    c.step(m)
    m.fresh = True
    c.step(m)
    assert c.xhat.x == pytest.approx(20e-6 / c.k_dft_hat, rel=1e-12)  # re-anchored after the gap
    assert c.pos_sup.active == 0 and len(j_before) == len(c.pos_bank.j)


def _x_hat_per_sample(
    res: SimResult, slips: bool, samples_known: bool, observe: bool = False
) -> dict[int, float]:
    """Feed a recorded fault-free run's sensor samples to a fresh mmac controller; with
    ``slips``, from 0.15 s on, every 50 samples in turn the way a realtime loop slips against
    the sensor's clock: a frame that came too late (a cycle without data, then that sample:
    1 sample after 1 dead cycle) and two samples within one cycle (the older superseded: the
    cycle gets 2 samples on, no dead cycle). Returns x̂ (m) after each sample stepped on."""
    c = make_controller("mmac", PARAMS, TS, reference=FAULT_FREE.reference)
    m = Measurement()
    out: dict[int, float] = {}
    k, last, n = 0, -1, len(res.y_s_m)
    while k < n:
        if slips and k >= 150 and k % 50 == 0 and k - 1 in out:
            if (k // 50) % 2:  # late frame: this cycle has no data, the next one gets sample k
                m.fresh = False
                c.step(m)
            else:  # superseded: sample k is not stepped on, the cycle gets k + 1
                if observe:  # the daemon hands the superseded sample to ``observe``
                    m.position_m, m.spool_m = float(res.y_s_m[k]), float(res.spool_m[k])
                    m.coil_current_a = float(res.current_a[k - 1])
                    m.samples, last = k - last, k
                    c.observe(m)
                k += 1
        m.position_m, m.spool_m = float(res.y_s_m[k]), float(res.spool_m[k])
        m.coil_current_a = float(res.current_a[k - 1]) if k else 0.0
        m.reference_m = float(res.x_d_m[k])
        m.fresh = True
        m.samples = (k - last if last >= 0 else 0) if samples_known else 0
        last = k
        c.step(m)
        out[k] = c.xhat.x
        k += 1
    return out


def test_mmac_keeps_x_hat_on_the_sensor_sample_clock() -> None:
    """With the E2E sample count (``Measurement.samples``), late and superseded frames leave x̂
    where it is without slips (redone over the samples that passed, the one not seen from the
    valve model: a fraction of a µm); without it each superseded sample leaves x̂ a sample of
    travel (≈ Ts·ẋ, up to 5 µm on this 1 mm, 5 rad/s sine) behind, for the anchor to remove
    slowly."""
    res = run_scenario(FAULT_FREE, "nrc")
    plain = _x_hat_per_sample(res, slips=False, samples_known=True)

    def worst(xh: dict[int, float]) -> float:
        return max(abs(v - plain[k]) for k, v in xh.items())

    # 40 superseded samples: each costs the unseen spool's prediction error (0.1–0.5 µm of x̂
    # here, decaying at the anchor rate) with the count, a sample of travel without it
    assert worst(_x_hat_per_sample(res, slips=True, samples_known=True)) < 1.5e-6
    assert worst(_x_hat_per_sample(res, slips=True, samples_known=False)) > 4e-6
    # the superseded samples observed (as the daemon does with a burst): x̂ integrates their
    # own spool; what is left is the anchor's pull on the samples not stepped on
    assert worst(_x_hat_per_sample(res, slips=True, samples_known=True, observe=True)) < 0.05e-6


def test_mmac_undoes_a_cycle_without_data_before_the_next_sample() -> None:
    """A frame that comes a cycle late (a cycle without data, then the next sample, counted 1
    on): the dead-reckoned cycle is undone and x̂ steps once, as if the cycle had not been there,
    whether or not the echo matches the commands this controller sent (offset: it does not)."""
    res = run_scenario(FAULT_FREE, "nrc")

    def run(late: bool, echo_offset_a: float) -> list[float]:
        c = make_controller("mmac", PARAMS, TS, reference=FAULT_FREE.reference)
        m, out = Measurement(), []
        for k in range(400):
            if late and k >= 150 and k % 50 == 0:
                m.fresh = False
                c.step(m)
            m.position_m, m.spool_m = float(res.y_s_m[k]), float(res.spool_m[k])
            m.coil_current_a = (float(res.current_a[k - 1]) if k else 0.0) + echo_offset_a
            m.reference_m, m.fresh, m.samples = float(res.x_d_m[k]), True, 1 if k else 0
            c.step(m)
            out.append(c.xhat.x)
        return out

    for offset in (0.0, 2e-4):
        plain, late = run(False, offset), run(True, offset)
        assert max(abs(a - b) for a, b in zip(plain, late, strict=True)) < 1e-12


def test_bridge_spool_removes_an_error_at_both_ends_and_splits_one_that_changed() -> None:
    """The spool over samples not seen: the model's gain·v plus the error seen at the two ends,
    interpolated; an error that changed inside the span is bounded by half of it over the span."""
    v = [1e-3, 1.2e-3, 0.8e-3]  # 3 samples not seen, a span of 4 periods
    same = bridge_spool(v, 0.5, 2e-4, 2e-4)  # k_LOE is 0.7 already: the error is 0.2·v at both ends
    assert same == pytest.approx([0.5 * x + 2e-4 for x in v], abs=1e-15)
    split = bridge_spool(v, 1.0, 0.0, -4e-4)  # it changed inside: the error grows 1/4 per period
    assert split == pytest.approx([1e-3 - 1e-4, 1.2e-3 - 2e-4, 0.8e-3 - 3e-4], abs=1e-15)
    assert bridge_bound_m(3.3e-3 * 3, -4e-4) == pytest.approx(0.5 * 3.3e-3 * 3 * 4e-4)


def test_span_currents_are_the_commands_sent_only_when_the_loop_ran_and_the_echo_agrees() -> None:
    """Sensor frames lost while this loop ran (a cycle per sample) and the echo is the command sent
    two cycles back: the commands sent, oldest first. A late emulator (fewer cycles than
    samples), an echo that disagrees or a superseded sample: the held echoes."""
    wire = deque([1e-4, 2e-4, 3e-4, 4e-4, 5e-4])  # sent 5 … 1 cycles ago
    assert span_currents(1, 0, wire, 9e-4, 4e-4, MATCH_A) == []
    assert span_currents(4, 3, wire, 9e-4, 4e-4, MATCH_A) == [1e-4, 2e-4, 3e-4]
    held = [9e-4, 4e-4, 4e-4]
    assert span_currents(4, 0, wire, 9e-4, 4e-4, MATCH_A) == held  # the emulator was late
    assert span_currents(4, 3, wire, 9e-4, 4.5e-4, MATCH_A) == [9e-4, 4.5e-4, 4.5e-4]  # echo disagrees
    assert span_currents(4, 3, None, 9e-4, 4e-4, MATCH_A) == held


def test_mmac_through_sensor_blackouts_at_fault_onsets() -> None:
    """Case 3 with sensor-frame blackouts (5 and 14 samples, two starting at a fault onset; the
    commands keep flowing): x̂ is bridged over them on the commands sent and the spool LVDT at
    both ends, so the position bank keeps θ̂_D on the drift. Before (x̂ on the last echo and a
    stale k̂_LOE): θ̂_D 2–3 % off for seconds and 7.1 µm RMS."""
    sc = load_scenario(PROJECT_ROOT / "scenarios" / "extra" / "unseen-blackouts.yaml")
    res = run_scenario(sc, "mmac")
    assert float(np.sqrt(np.mean(res.error_m**2))) < 2.5e-6
    for t0, t1 in ((2.1, 2.45), (2.6, 3.0)):  # after the blackouts at the LOE onset and later
        kd = res.k_dft_hat[round(t0 / TS) : round(t1 / TS)]
        assert float(np.max(np.abs(kd - 0.8))) < 0.006


def test_mmac_after_a_reset_mid_motion_starts_from_the_sensor() -> None:
    """Leaving the fail-safe resets the controller while the plant is away from 0: x̂ starts on
    the first sensor sample, the position channel stays out of guard and the sensor is fed back
    (before, x̂ began at 0, the guard tripped at once and the loop fed back x̂: a runaway)."""
    res = run_scenario(FAULT_FREE, "nrc")
    c = make_controller("mmac", PARAMS, TS, reference=FAULT_FREE.reference)
    assert isinstance(c, MmacController)
    m = Measurement()
    k0 = 300  # ≈ 0.9 mm into the sine
    for k in range(k0, k0 + 20):
        m.position_m, m.spool_m = float(res.y_s_m[k]), float(res.spool_m[k])
        m.coil_current_a, m.reference_m = float(res.current_a[k - 1]), float(res.x_d_m[k])
        m.samples = 1 if k > k0 else 0
        c.step(m)
        assert not c.pos_sup.guarded and c.sensor_trusted
        assert abs(c.xhat.x - float(res.x_true_m[k])) < 5e-6


def test_one_mode_registry() -> None:
    """The configuration's mode choices, the daemon's and the CTRL_STATUS codes are the
    registry's (and the DBC's value table names the same codes)."""
    from typing import get_args

    from ehpss_hil import config
    from ehpss_hil.codec import FrameCodec
    from ehpss_hil.control.registry import DAEMON_MODES, MODE_CODE, REGISTRY

    assert get_args(config.Mode) == MODES == tuple(REGISTRY)
    assert config.DAEMON_MODES == DAEMON_MODES and "oracle" not in DAEMON_MODES
    choices = FrameCodec().message("CTRL_STATUS").get_signal_by_name("Mode").choices
    assert choices is not None
    assert {str(choices[c]): c for c in MODE_CODE.values()} == MODE_CODE
