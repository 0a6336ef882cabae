"""A sensor gain change after the position regression was started over mid-stroke.

The position channel regresses ``y_s − y0`` on ``x̂ − x0``. Started over at a point away from
the sensor's zero — x̂ re-anchored on the sensor after a blackout, or seeded after a restart (a
watchdog's recovery resets the controller) — a later sensor gain change, which scales the reading
about its zero, used to read as an offset of (gain change × that point): 69 µm RMS (blackout) and
71 µm (restart) on the runs below, against 0.5 µm without either. Deterministic lockstep runs.
"""

from __future__ import annotations

from collections import deque
from dataclasses import replace

import numpy as np

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.codec.frames import FrameCodec
from ehpss_hil.control.estimates import Estimates
from ehpss_hil.control.evidence.increments import Increments
from ehpss_hil.control.predictors import ModelPosition
from ehpss_hil.control.registry import make_controller
from ehpss_hil.driver import ControllerDriver
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.physics.load import load_params
from ehpss_hil.report.metrics import compute_metrics
from ehpss_hil.scenario import Scenario, load_scenario
from ehpss_hil.sim import run_scenario
from ehpss_hil.sim.lockstep import reference_output
from ehpss_hil.sim.transport import QuantizeTransport

PARAMS = load_params()
UM = 1e-6
BLACKOUT = PROJECT_ROOT / "scenarios" / "envelope" / "blackout-midstroke-drift.yaml"


def test_a_drift_after_a_blackout_mid_stroke_is_compensated() -> None:
    """Sensor frames lost for 50 ms at x = −0.5 mm (x̂ re-anchored there), a drift 0.8 at the other
    end of the stroke 0.85 s later: within 5 µm of the oracle (it was 68.6 µm against 4.7)."""
    sc = load_scenario(BLACKOUT)
    mm = compute_metrics(run_scenario(sc, "mmac", PARAMS))
    oracle = compute_metrics(run_scenario(sc, "oracle", PARAMS))
    assert mm.rms_error_m <= oracle.rms_error_m + 5 * UM


def _rms_with_restart(sc: Scenario, restart_s: float | None) -> float:
    """RMS of x − y_m (m) of mmac on ``sc``, its controller reset at ``restart_s`` as a watchdog's
    recovery does (the driver and the bus go on)."""
    ts = sc.sample_time_s
    ctrl = make_controller("mmac", PARAMS, ts, None, sc.reference)
    emu = PlantEmulation(PARAMS, sc, None)
    tr = QuantizeTransport(FrameCodec())
    x_d = sc.reference_samples()
    y_m = reference_output(PARAMS, ts, x_d)
    drv = ControllerDriver(ctrl, x_d.tolist().__getitem__)
    queue: deque[float | None] = deque([0.0] * sc.transport_delay_samples)
    held, err = 0.0, []
    k_reset = -1 if restart_s is None else round(restart_s / ts)
    for k in range(len(x_d)):
        if k == k_reset:
            ctrl.reset()
        _, _, pos, spool, pressure, coil, x_true, _, _, saturated = emu.sample()
        lost_sensor, lost_command = emu.frame_losses()
        tr.sensor(drv, k, pos, spool, pressure, coil, saturated, lost_sensor)
        current, enable = drv.step()
        queue.append(tr.command(current if enable else 0.0, k, lost_command))
        arrived = queue.popleft()
        held = held if arrived is None else arrived
        err.append(x_true - y_m[k])
        emu.advance(held)
    return float(np.sqrt(np.mean(np.square(err))))


def test_a_drift_after_a_restart_mid_stroke_is_compensated() -> None:
    """The blackout run without the blackout, the controller restarted at x = −0.8 mm instead
    (2.07 s, after the LOE): the drift 0.8 at 2.9 s is compensated within 5 µm of the same run
    without the restart (it was 70.8 µm against 0.5)."""
    sc = load_scenario(BLACKOUT)
    sc = replace(sc, events=tuple(e for e in sc.events if e.sensor_frame_loss is None))
    assert [e.t_s for e in sc.events] == [1.5, 2.9]
    assert _rms_with_restart(sc, 2.07) <= _rms_with_restart(sc, None) + 5 * UM


def test_the_regression_goes_through_the_sensors_zero_once_rebased() -> None:
    """``pivot_to_zero``: x̂ re-based on θ (x0 = y0/θ) ⇒ pivot (0, 0), x̂ unchanged; a pivot the
    re-base limit refused is kept."""
    est = Estimates(ModelPosition(PARAMS.plant, 1e-3, 0.0), failed_below=0.1, rebase_limit_m=1e-3)
    est.reanchor(-0.8e-3, -0.81e-3)
    est.rebase(0.9, True)
    assert est.x0 == est.y0 / 0.9
    x_hat = est.xhat.x
    est.pivot_to_zero(0.9)
    assert (est.y0, est.x0, est.xhat.x) == (0.0, 0.0, x_hat)
    est.reanchor(-0.8e-3, -0.81e-3)
    est.rebase(0.3, True)  # x0 would move by 1.9 mm: refused
    est.pivot_to_zero(0.3)
    assert (est.y0, est.x0) == (-0.8e-3, -0.81e-3)


def test_the_increments_confirm_the_gain_they_settled_on_only() -> None:
    """``Increments.confirms``: settled within min_deviation/2 of the gain asked about; nothing
    is confirmed before the product has settled."""
    inc = Increments(PARAMS.plant, 1e-3, 1.5e-3)
    rng = np.random.default_rng(5)
    x, k_c, ts = 0.0, PARAMS.plant.velocity_gain_1_s, 1e-3
    assert not inc.confirms(1.0)
    for _ in range(300):
        x += k_c * 1.5e-3 * ts
        inc.product(0.9 * x + 5e-7 * rng.standard_normal(), 1.5e-3)
    assert inc.product_settled
    assert inc.confirms(0.9) and not inc.confirms(1.0) and not inc.confirms(0.85)
