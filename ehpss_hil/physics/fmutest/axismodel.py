"""The test FMU's plant logic, shared by its FMI 2.0 slave (:mod:`.ehpss_axis`, pythonfmu) and its
FMI 3.0 slave (:mod:`.ehpss_axis3`, pythonfmu3): our own nonlinear valve-controlled cylinder
(:class:`~ehpss_hil.physics.hydraulics.NonlinearPlant` on the shipped params.yaml).

One communication step is one plant sample: the plant is discretized for the step size of the
first step (:data:`STEP_S` by default); a later step of another size fails. The FMI variables are
attributes of the slave (pythonfmu reads and writes them by name): inputs ``current_a`` (A),
``k_loe``, ``k_q`` (1); outputs ``position_m``, ``spool_m`` (m), ``load_pressure_pa`` (Pa),
``current_echo_a`` (A).
"""

from __future__ import annotations

from ehpss_hil.physics.faults import FaultState
from ehpss_hil.physics.hydraulics import NonlinearPlant, derive
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.plantspec import PlantSpec

#: the default experiment's step size (s): one sample of the bench's 1 kHz loop
STEP_S = 1e-3
#: inputs: coil current (A), the actuator fault gains k_LOE and k_Q (1 = healthy)
INPUTS = ("current_a", "k_loe", "k_q")
#: outputs: piston position (m), actual spool (m), load pressure (Pa), coil-current echo (A)
OUTPUTS = ("position_m", "spool_m", "load_pressure_pa", "current_echo_a")
#: the relative tolerance within which a step size counts as the one the plant was built for
_STEP_RTOL = 1e-12


class AxisModel:
    """The plant behind the FMU's variables; a slave calls :meth:`init_axis` in its constructor
    and :meth:`advance` from its ``do_step``."""

    def init_axis(self) -> None:
        """Inputs healthy and at rest, outputs of the plant at rest, built for :data:`STEP_S`."""
        self.current_a, self.k_loe, self.k_q = 0.0, 1.0, 1.0
        self.position_m, self.load_pressure_pa, self.current_echo_a = 0.0, 0.0, 0.0
        self._ts_s = STEP_S
        self._plant = self._build(STEP_S)
        self._faults = (1.0, 1.0)

    @staticmethod
    def _build(ts_s: float) -> NonlinearPlant:
        plant = load_params().plant
        return NonlinearPlant(derive(plant, PlantSpec(model="nonlinear")), plant, ts_s)

    def actual_spool_m(self) -> float:
        """Actual spool k_LOE·x_v (m) with the k_LOE input as set now (the getter of the
        ``spool_m`` output: it feeds k_loe through at once, as the built-in plant's does)."""
        return self.k_loe * self._plant.spool_commanded_m

    def publish(self) -> None:
        """The plant's position and load pressure → the output variables."""
        p = self._plant
        self.position_m = p.position_m
        self.load_pressure_pa = p.load_pressure_pa

    def advance(self, current_time: float, step_size: float) -> bool:
        """One sample of ``step_size`` (s) with the inputs held; False (the step fails) for a
        step size other than the first one's."""
        if abs(step_size - self._ts_s) > _STEP_RTOL * self._ts_s:
            if current_time > 0.0:
                return False
            self._ts_s, self._plant = step_size, self._build(step_size)
        faults = (self.k_loe, self.k_q)
        if faults != self._faults:
            self._plant.set_faults(FaultState(k_loe=faults[0], k_q=faults[1]))
            self._faults = faults
        self.current_echo_a = self._plant.step(self.current_a)
        self.publish()
        return True
