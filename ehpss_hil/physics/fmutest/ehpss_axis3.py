"""The test FMU's FMI 3.0 model (a pythonfmu3 ``Fmi3Slave``): the same plant as the FMI 2.0 one
(:class:`.axismodel.AxisModel`) behind the FMI 3.0 co-simulation interface (``Float64``
variables, ``fmi3DoStep`` with its ``terminateSimulation`` flag), so that the bench's FMI 3.0 path
runs in the test suite.

Hostile variants (the builder in :mod:`ehpss_hil.physics.fmutest` writes a copy with one set):
:data:`FAIL_AT_S`, every step from that time on returns fmi3Discard; :data:`TERMINATE_AT_S`, the
step at that time returns fmi3OK but asks the importer to terminate (FMI 3.0 only). This file is
read by pythonfmu3's builder; nothing in the package imports it.
"""

from __future__ import annotations

from typing import Any

from pythonfmu3 import DefaultExperiment, Float64, Fmi3Causality, Fmi3Slave, Fmi3StepResult, Fmi3Variability

from ehpss_hil.physics.fmutest.axismodel import INPUTS, OUTPUTS, STEP_S, AxisModel

#: every step at or after this time (s) returns fmi3Discard; None: never
FAIL_AT_S: float | None = None
#: the step at or after this time (s) sets terminateSimulation; None: never
TERMINATE_AT_S: float | None = None
#: slack when comparing communication points k·Ts with those times (s)
_EPS_S = 1e-9


class EhpssAxis3(AxisModel, Fmi3Slave):  # type: ignore[misc]
    """The nonlinear plant behind the FMI 3.0 co-simulation interface."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.description = "ehpss-hil's nonlinear valve-controlled cylinder (test FMU, FMI 3.0)"
        self.default_experiment = DefaultExperiment(start_time=0.0, step_size=STEP_S)
        self.init_axis()
        self.time = 0.0
        continuous = Fmi3Variability.continuous
        self.register_variable(Float64("time", causality=Fmi3Causality.independent, variability=continuous))
        for name in INPUTS:
            self.register_variable(Float64(name, causality=Fmi3Causality.input, variability=continuous))
        for name in OUTPUTS:
            getter = self.actual_spool_m if name == "spool_m" else None
            self.register_variable(
                Float64(name, causality=Fmi3Causality.output, variability=continuous, getter=getter)
            )

    def exit_initialization_mode(self) -> None:
        self.publish()

    def do_step(self, current_time: float, step_size: float) -> Fmi3StepResult | bool:
        if FAIL_AT_S is not None and current_time >= FAIL_AT_S - _EPS_S:
            return False
        if not self.advance(current_time, step_size):
            return False
        self.time = current_time + step_size
        if TERMINATE_AT_S is not None and current_time >= TERMINATE_AT_S - _EPS_S:
            return Fmi3StepResult(terminateSimulation=True)
        return True
