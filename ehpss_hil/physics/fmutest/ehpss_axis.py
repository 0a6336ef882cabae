"""The test FMU's model (a pythonfmu ``Fmi2Slave``): our own nonlinear valve-controlled cylinder
(:class:`~ehpss_hil.physics.hydraulics.NonlinearPlant` on the shipped params.yaml) as an FMI 2.0
co-simulation FMU, so that ``plant: {model: fmu}`` can be checked against ``model: nonlinear``.

One communication step is one plant sample: the plant is discretized for the step size of the
first ``do_step`` (1 ms by default, :data:`STEP_S`); a later step of another size fails.
:data:`FAIL_AT_S` makes every step from that time on fail (the hostile FMU of the tests; the
builder in :mod:`ehpss_hil.physics.fmutest` writes a copy with it set). This file is read by
``pythonfmu build``; nothing in the package imports it.
"""

from __future__ import annotations

from typing import Any

from pythonfmu import DefaultExperiment, Fmi2Causality, Fmi2Slave, Fmi2Variability, Real

from ehpss_hil.physics.faults import FaultState
from ehpss_hil.physics.hydraulics import NonlinearPlant, derive
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plantspec import PlantSpec

#: the default experiment's step size (s): one sample of the bench's 1 kHz loop
STEP_S = 1e-3
#: every step at or after this time (s) returns fmi2Error; None: never
FAIL_AT_S: float | None = None
#: inputs: coil current (A), the actuator fault gains k_LOE and k_Q (1 = healthy)
INPUTS = ("current_a", "k_loe", "k_q")
#: outputs: piston position (m), actual spool (m), load pressure (Pa), coil-current echo (A)
OUTPUTS = ("position_m", "spool_m", "load_pressure_pa", "current_echo_a")


class EhpssAxis(Fmi2Slave):  # type: ignore[misc]
    """The nonlinear plant behind the FMI 2.0 co-simulation interface."""

    def __init__(self, **kwargs: Any) -> None:
        super().__init__(**kwargs)
        self.description = "ehpss-hil's nonlinear valve-controlled cylinder (test FMU)"
        self.default_experiment = DefaultExperiment(start_time=0.0, step_size=STEP_S)
        self.current_a, self.k_loe, self.k_q = 0.0, 1.0, 1.0
        self.position_m, self.load_pressure_pa, self.current_echo_a = 0.0, 0.0, 0.0
        for name in INPUTS:
            self.register_variable(
                Real(name, causality=Fmi2Causality.input, variability=Fmi2Variability.continuous)
            )
        for name in OUTPUTS:
            # the actual spool feeds k_loe through at once (as the built-in plant's does)
            getter = self._spool_m if name == "spool_m" else None
            self.register_variable(
                Real(
                    name,
                    causality=Fmi2Causality.output,
                    variability=Fmi2Variability.continuous,
                    getter=getter,
                )
            )
        self._ts_s = STEP_S
        self._plant = self._build(STEP_S)
        self._faults = (1.0, 1.0)

    @staticmethod
    def _build(ts_s: float) -> NonlinearPlant:
        plant = load_params().plant
        spec = PlantSpec(model="nonlinear")
        return NonlinearPlant(derive(plant, spec), plant, ts_s)

    def _spool_m(self) -> float:
        """Actual spool k_LOE·x_v (m) with the k_LOE input as set now."""
        return self.k_loe * self._plant.spool_commanded_m

    def _publish(self) -> None:
        p = self._plant
        self.position_m = p.position_m
        self.load_pressure_pa = p.load_pressure_pa

    def exit_initialization_mode(self) -> None:
        self._publish()

    def do_step(self, current_time: float, step_size: float) -> bool:
        if FAIL_AT_S is not None and current_time >= FAIL_AT_S - 1e-9:
            return False
        if abs(step_size - self._ts_s) > 1e-12 * self._ts_s:
            if current_time > 0.0:
                return False
            self._ts_s, self._plant = step_size, self._build(step_size)
        faults = (self.k_loe, self.k_q)
        if faults != self._faults:
            self._plant.set_faults(FaultState(k_loe=faults[0], k_q=faults[1]))
            self._faults = faults
        self.current_echo_a = self._plant.step(self.current_a)
        self._publish()
        return True
