"""The identification experiment in lockstep: the emulated plant a scenario describes, its
sensors and frame layer, the PI loop (the nrc controller) tracking the excitation reference.

The controller is run by the one :class:`~ehpss_hil.driver.ControllerDriver`; unlike the
simulator's loop (:mod:`ehpss_hil.sim.lockstep`) this one checks the experiment's limits every
sample — measured travel, measured spool, commanded current — and on the first crossing goes to
fail-safe (0 A) and stops with :class:`ExperimentAborted` naming the limit. It records what the
controller side receives: position, spool, load pressure and the current echo (the current the
valve applied over the previous sample), NaN where a sample's frames were lost.
"""

from __future__ import annotations

from collections import deque
from dataclasses import dataclass, replace

import numpy as np
from numpy.typing import NDArray

from ..codec.frames import FrameCodec
from ..control.registry import make_controller
from ..driver import ControllerDriver
from ..emulation import PlantEmulation
from ..errors import EhpssError
from ..physics.params import Params
from ..scenario import Disturbance, Scenario
from ..sim.transport import QuantizeTransport
from .excitation import Excitation

Array = NDArray[np.float64]


class ExperimentAborted(EhpssError):
    """A limit of the experiment was crossed: the loop went to fail-safe (0 A) and stopped."""

    exit_code = 1


@dataclass
class Record:
    """What the controller side measured, one entry per sample (SI; NaN: frames lost).

    ``applied_a[k]`` is the current held over [k, k+1): the echo of sample k+1, or, where that
    echo was lost, the command the valve was sent for that interval.
    """

    ts_s: float
    x_d_m: Array
    position_m: Array
    spool_m: Array
    load_pressure_pa: Array
    applied_a: Array
    #: samples per period of the excitation (the report's FFT runs over whole periods)
    period_samples: int


def experiment_scenario(scenario: Scenario, exc: Excitation) -> Scenario:
    """``scenario``'s plant, noise, frame loss, delay and seed, fault-free and undisturbed, for
    the experiment's duration."""
    duration = exc.period_s * exc.periods
    return replace(scenario, duration_s=duration, events=(), disturbance=Disturbance(kind="none"))


def run_experiment(scenario: Scenario, exc: Excitation, params: Params) -> Record:
    """Run the excitation around the nrc PI (gains from ``params``) against the emulated plant
    of ``scenario`` (its ``plant:`` section over ``params.plant``); returns the measurements."""
    sc = experiment_scenario(scenario, exc)
    ts = sc.sample_time_s
    x_d = exc.reference(ts)
    n = len(x_d)
    emu = PlantEmulation(params, sc)
    tr = QuantizeTransport(FrameCodec())
    drv = ControllerDriver(make_controller("nrc", params, ts), x_d.__getitem__)
    delay = sc.transport_delay_samples
    queue: deque[float | None] = deque([0.0] * delay)
    sent: deque[float] = deque([0.0] * delay)
    out = np.full((n, 5), np.nan)  # position, spool, pressure, echo, the command held
    held = 0.0
    for k in range(n):
        s = emu.measure()
        if tr.sensor(
            drv,
            k,
            s.position_m,
            s.spool_m,
            s.load_pressure_pa,
            s.coil_current_a,
            s.current_saturated,
            emu.frame_lost(0),
        ):
            m = drv.meas
            _check(m.position_m, exc.travel_limit_m, "travel |y_s|", k, ts)
            _check(m.spool_m, exc.spool_limit_m, "spool |x_v|", k, ts)
            out[k, :4] = m.position_m, m.spool_m, m.load_pressure_pa, m.coil_current_a
        current, enable = drv.step()
        _check(current, exc.current_limit_a, "current |I|", k, ts)
        cmd = current if enable else 0.0
        queue.append(tr.command(cmd, k, emu.frame_lost(1)))
        sent.append(cmd)
        arrived, expected = queue.popleft(), sent.popleft()
        if arrived is not None:
            held = arrived
        out[k, 4] = held if arrived is not None else expected
        emu.advance(held)
    echo = np.append(out[1:, 3], np.nan)
    applied = np.where(np.isfinite(echo), echo, out[:, 4])
    return Record(ts, x_d, out[:, 0], out[:, 1], out[:, 2], applied, round(exc.period_s / ts))


def _check(value: float, limit: float, what: str, k: int, ts_s: float) -> None:
    """Fail-safe on a crossed limit (the valve gets no further command: 0 A)."""
    if abs(value) > limit:
        raise ExperimentAborted(
            f"identification stopped in fail-safe at t = {k * ts_s:.3f} s: {what} = {abs(value):.4g} "
            f"exceeds its limit {limit:.4g} (SI units); lower --amplitude or raise the limit"
        )
