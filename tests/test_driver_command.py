"""The command :meth:`~ehpss_hil.driver.ControllerDriver.step` hands on: the controller's current
clipped to ±``current_limit_a``, a non-finite one 0 A, each of those counted — also with an
infinite limit (the range test is written without calls; this pins what it must decide)."""

from __future__ import annotations

import math

import pytest

from ehpss_hil.control.base import Controller, Measurement, ValveCommand
from ehpss_hil.driver import ControllerDriver
from ehpss_hil.physics.params import Params


class _Fixed(Controller):
    """A law that commands the next current of a list, whatever it measures."""

    def __init__(self, currents: list[float]) -> None:
        self._currents = iter(currents)

    def configure(self, params: Params, ts_s: float) -> None:
        pass

    def reset(self) -> None:
        pass

    def step(self, meas: Measurement) -> ValveCommand:
        cmd = ValveCommand()
        cmd.current_a = next(self._currents)
        return cmd


CASES = [
    # limit, commanded, handed on, counted
    (1.0, 0.5, 0.5, False),
    (1.0, -1.0, -1.0, False),
    (1.0, 1.5, 1.0, True),
    (1.0, -2.5, -1.0, True),
    (1.0, math.nan, 0.0, True),
    (1.0, math.inf, 0.0, True),
    (1.0, -math.inf, 0.0, True),
    (math.inf, 3.0e6, 3.0e6, False),
    (math.inf, math.inf, 0.0, True),
    (math.inf, -math.inf, 0.0, True),
    (math.inf, math.nan, 0.0, True),
]


@pytest.mark.parametrize(("limit", "commanded", "handed", "counted"), CASES)
def test_step_clips_and_counts(limit: float, commanded: float, handed: float, counted: bool) -> None:
    drv = ControllerDriver(_Fixed([commanded]), lambda k: 0.0, current_limit_a=limit)
    drv.sensors(0.0, 0.0, 0, 0.0, 0.0)
    current, _ = drv.step()
    assert current == handed and math.copysign(1.0, current) == math.copysign(1.0, handed)
    assert drv.saturations == (1 if counted else 0)
