"""The one controller contract shared by the lockstep simulator, the daemon and replay."""

from __future__ import annotations

from abc import ABC, abstractmethod
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Protocol

from ..physics.params import Params, PlantParams


class NominalMotion(Protocol):
    """The motion the loop is configured for, which sets the channels' nominal amplitudes S: a
    scenario's :class:`~ehpss_hil.scenario.Reference` is one."""

    @property
    def amplitude_m(self) -> float:
        """Nominal position amplitude (m)."""
        ...

    @property
    def spool_amplitude_m(self) -> float:
        """Nominal spool amplitude the motion needs (m)."""
        ...


@dataclass(frozen=True)
class PaperMotion:
    """The paper's 1 mm, 5 rad/s sine: 1 mm of position, r·ω/K_c ≈ 1.52 mm of spool (K_c of the
    default plant, :attr:`PlantParams.velocity_gain_1_s`, as :class:`~ehpss_hil.scenario.Reference`
    uses it)."""

    amplitude_m: float = 1e-3
    spool_amplitude_m: float = 1e-3 * 5.0 / PlantParams().velocity_gain_1_s


@dataclass(slots=True)
class Measurement:
    """One cycle's decoded sensor data, SI units.

    ``position_m``: position sensor y_s = k_DFT·x (+ noise, bias) (m).
    ``spool_m``: spool LVDT k_LOE·x_v (+ noise) (m).
    ``coil_current_a``: current the valve amplifier applied during the last sample (A).
    ``load_pressure_pa``: P_L (Pa), logged, not used for identification.
    ``reference_m``: desired position x_d for this cycle (m).
    ``fresh``: False when no valid sensor frame arrived this cycle (values are the last valid ones).
    ``samples``: sensor samples from the previous fresh measurement to this one, from the
    frames' E2E counter (1: the next sample; 2: one sample between them was lost or superseded
    in the same cycle; 0: unknown, taken as one per cycle). A realtime loop's cycles slip against
    the sensor's sample clock; this keeps the model position on the sample clock (docs/design.md §5,
    docs/control.md §3).
    ``command_sent``: False when this cycle's command will not be sent (a period the loop slept
    through, stepped only to keep its clock on the grid): the valve keeps the previous one.
    """

    position_m: float = 0.0
    spool_m: float = 0.0
    coil_current_a: float = 0.0
    load_pressure_pa: float = 0.0
    reference_m: float = 0.0
    fresh: bool = True
    samples: int = 0
    command_sent: bool = True


#: a sensor sample superseded within a cycle, kept for ``observe``: position (m), spool (m),
#: current echo (A), load pressure (Pa), and the E2E counter of its SENSOR_POS
HeldSample = tuple[float, float, float, float, int]


def hold_sample(m: Measurement, counter: int) -> HeldSample:
    """The sensor values of ``m`` (SENSOR_POS with ``counter`` and its SENSOR_AUX), kept."""
    return (m.position_m, m.spool_m, m.coil_current_a, m.load_pressure_pa, counter)


def observe_held(
    observe: Callable[[Measurement], None],
    held: list[HeldSample],
    samples_of: Callable[[int], int],
    scratch: Measurement,
) -> None:
    """Hand the held samples to ``observe`` in order (``samples_of(counter)``: sensor samples
    since the one stepped or observed before), then forget them. The daemon calls it after the
    caught-up periods and before the cycle's step; ``replay`` does the same."""
    for scratch.position_m, scratch.spool_m, scratch.coil_current_a, scratch.load_pressure_pa, c in held:
        scratch.samples = samples_of(c)
        observe(scratch)
    held.clear()


@dataclass(slots=True)
class ValveCommand:
    """The controller's output for one cycle: coil current setpoint (A) and enable."""

    current_a: float = 0.0
    enable: bool = True


@dataclass
class ControllerStatus:
    """Read-only view of a controller's internals (for CTRL_STATUS / CTRL_INDEX and reports).

    ``active_model``: channel name → active model slot (DBC CTRL_INDEX ModelSlot numbering).
    ``k_loe_hat``/``k_dft_hat``: the estimates used for compensation (dimensionless; in ``mmac``
    ``k_loe_hat`` is the current divisor k̂_LOE·k̂_Q). ``k_q_hat``: the flow-gain attribution.
    ``index``: slot → performance index J; ``theta``: slot → the model's parameter θ.
    ``fallback``/``fallback_reason``/``fallbacks``: the do-no-harm monitor's state.
    """

    mode: str = "nrc"
    active_model: dict[str, int] = field(default_factory=dict)
    k_loe_hat: float = 1.0
    k_dft_hat: float = 1.0
    k_q_hat: float = 1.0
    index: dict[int, float] = field(default_factory=dict)
    theta: dict[int, float] = field(default_factory=dict)
    switches: int = 0
    #: the do-no-harm monitor holds the loop on nominal compensation (control/monitor.py), why
    #: (FallbackReason) and how often it did since start-up
    fallback: bool = False
    fallback_reason: int = 0
    fallbacks: int = 0


class Controller(ABC):
    """A discrete-time position controller running at a fixed sample time: the one contract the
    daemon, replay, the lockstep simulator and sample logs drive (through
    :class:`~ehpss_hil.driver.ControllerDriver`). Every mode of
    :mod:`~ehpss_hil.control.registry` and every custom law (``--controller-factory``) is one.

    A law implements :meth:`configure`, :meth:`reset` and :meth:`step`; the rest has defaults
    for a law without model banks: :meth:`observe` ignores a superseded sample, :meth:`probe`
    reports no active model and nominal estimates, :meth:`status` is built from the probes.
    """

    #: the mode name (a key of the registry; CTRL_STATUS ``Mode``)
    mode: str = "custom"
    #: the model slots (DBC CTRL_INDEX ``ModelSlot``) :meth:`index_values` and
    #: :meth:`theta_values` report, in their order
    index_slots: tuple[int, ...] = ()
    #: the do-no-harm fallback holds the loop on nominal compensation now
    nominal: bool = False

    @abstractmethod
    def configure(self, params: Params, ts_s: float) -> None:
        """Build every matrix, gain and buffer for sample time ``ts_s`` (s); nothing is
        allocated in :meth:`step` afterwards."""

    @abstractmethod
    def reset(self) -> None:
        """Back to the initial state (integrators, estimates, indices, active models); what a
        law learned of the plant itself (mmac: its flow gain, the pressure baseline) is kept —
        leaving the fail-safe does not change the plant; :meth:`configure` forgets it."""

    @abstractmethod
    def step(self, meas: Measurement) -> ValveCommand:
        """One cycle: measurement in, valve command out."""

    def observe(self, meas: Measurement) -> None:
        """A sensor sample that a newer one superseded within the same cycle (a burst of late
        frames), handed over before the cycle's :meth:`step`: a law that keeps predictors on the
        sample clock steps them on it (no regression, no output). Default: ignored."""
        return None

    def probe(self) -> tuple[int, int, float, float]:
        """(active spool slot, active position slot, k̂_LOE, k̂_DFT): cheap, every sample.
        Default: no bank (-1, -1) and the nominal estimates 1, 1."""
        return (-1, -1, 1.0, 1.0)

    def index_values(self) -> list[float]:
        """J of every model in :attr:`index_slots` order (dimensionless). Default: none."""
        return []

    def theta_values(self) -> list[float]:
        """θ of every model in :attr:`index_slots` order. Default: none."""
        return []

    def sample_record(self) -> tuple[float, ...]:
        """:meth:`probe` then :meth:`index_values`, flat in one tuple: what the lockstep
        simulator records every sample (a mode may build it in one step)."""
        return (*self.probe(), *self.index_values())

    def switch_count(self) -> int:
        """Total model switches since reset. Default: 0."""
        return 0

    def fallback_reason(self) -> int:
        """Why the loop compensates nominally now (FallbackReason; 0: it does not)."""
        return 0

    def fallback_count(self) -> int:
        """Entries into the nominal fallback since start-up."""
        return 0

    def status(self) -> ControllerStatus:
        """The current status from the probes (allocates: call at status-frame rate, not every
        cycle)."""
        sp, ps, kl, kd = self.probe()
        active = {}
        if sp >= 0:
            active["spool"] = sp
        if ps >= 0:
            active["position"] = ps
        return ControllerStatus(
            mode=self.mode,
            active_model=active,
            k_loe_hat=kl,
            k_dft_hat=kd,
            index=dict(zip(self.index_slots, self.index_values(), strict=True)),
            theta=dict(zip(self.index_slots, self.theta_values(), strict=True)),
            switches=self.switch_count(),
            fallback=self.nominal,
            fallback_reason=self.fallback_reason(),
            fallbacks=self.fallback_count(),
        )
