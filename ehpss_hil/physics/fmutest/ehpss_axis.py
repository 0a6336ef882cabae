"""The test FMU's FMI 2.0 model (a pythonfmu ``Fmi2Slave``): our own nonlinear valve-controlled
cylinder (:class:`.axismodel.AxisModel`) as an FMI 2.0 co-simulation FMU, so that
``plant: {model: fmu}`` can be checked against ``model: nonlinear``.

:data:`FAIL_AT_S` makes every step from that time on fail (the hostile FMU of the tests; the
builder in :mod:`ehpss_hil.physics.fmutest` writes a copy with it set). This file is read by
``pythonfmu build``; nothing in the package imports it.
"""

from __future__ import annotations

from typing import Any

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

from ehpss_hil.physics.fmutest.axismodel import INPUTS, OUTPUTS, STEP_S, AxisModel

#: every step at or after this time (s) returns fmi2Error; None: never
FAIL_AT_S: float | None = None


class EhpssAxis(AxisModel, Fmi2Slave):  # type: ignore[misc]
    """The nonlinear plant behind the FMI 2.0 co-simulation interface."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.description = "ehpss-hil's nonlinear valve-controlled cylinder (test FMU)"
        self.default_experiment = DefaultExperiment(start_time=0.0, step_size=STEP_S)
        self.init_axis()
        for name in INPUTS:
            self.register_variable(
                Real(name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous)
            )
        for name in OUTPUTS:
            getter = self.actual_spool_m if name == "spool_m" else None
            self.register_variable(
                Real(
                    name,
                    causality=Fmi2Causality.output,
                    variability=Fmi2Variability.continuous,
                    getter=getter,
                )
            )

    def exit_initialization_mode(self) -> None:
        self.publish()

    def do_step(self, current_time: float, step_size: float) -> bool:
        if FAIL_AT_S is not None and current_time >= FAIL_AT_S - 1e-9:
            return False
        return self.advance(current_time, step_size)
