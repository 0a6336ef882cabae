"""Scenario files (docs/design.md §10): reference, noise, frame loss, delay, disturbance, fault events.

A scenario is loaded into frozen dataclasses; any unknown key, wrong type, missing key or
out-of-range value raises :class:`~ehpss_hil.errors.ConfigError` naming file and key path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Literal

import numpy as np

from .errors import ConfigError
from .limits import (
    MAX_RATE_HZ,
    MAX_REFERENCE_M,
    MAX_SCENARIO_SAMPLES,
    MIN_RATE_HZ,
    MIN_REFERENCE_SCALE,
)
from .physics.faults import FaultState
from .physics.fmumap import ACTUATOR_FAULTS
from .physics.params import PlantParams
from .physics.plantspec import PlantSpec
from .schema import build, load_yaml, rng
from .trajectory import ReferenceTable, load_reference_table


@dataclass(frozen=True)
class Reference:
    """Desired position x_d(t) (m).

    kinds: ``sine`` (amplitude·sin(ω t)), ``step`` (amplitude from ``start_s``), ``ramp``
    (``rate_m_s``·(t − start_s), clipped to ±amplitude), ``square`` (±amplitude, period 2π/ω,
    from ``start_s``: +amplitude for the first half period), ``trapezoid`` (period 2π/ω from
    ``start_s``: ramps at ±|rate_m_s| between ±amplitude, a triangle when the ramps take the
    whole half period), ``file`` (CSV ``t_s,x_m``, linear interpolation, held after the end;
    :mod:`ehpss_hil.trajectory`).

    A non-zero ``amplitude_m`` or ``rate_m_s`` is at least
    :data:`~ehpss_hil.limits.MIN_REFERENCE_SCALE` in magnitude: the adaptive layer normalizes
    by the spool amplitude they imply. A loaded file reference holds its table (``table``, not a
    YAML key), read once by :meth:`loaded`; ``path`` is then absolute.
    """

    kind: Literal["sine", "step", "ramp", "square", "trapezoid", "file"] = "sine"
    amplitude_m: float = field(default=0.001, metadata=rng(0.0, MAX_REFERENCE_M))
    omega_rad_s: float = field(default=5.0, metadata=rng(0.0, 2000.0))
    start_s: float = field(default=0.0, metadata=rng(0.0))
    rate_m_s: float = field(default=0.001, metadata=rng(-1.0, 1.0))
    path: str = ""
    table: ReferenceTable | None = field(default=None, compare=False, repr=False, metadata={"internal": True})

    def __post_init__(self) -> None:
        if self.kind == "file" and not self.path:
            raise ConfigError("", "path", "required when kind is 'file'")
        for key in ("amplitude_m", "rate_m_s"):
            value = getattr(self, key)
            if 0.0 < abs(value) < MIN_REFERENCE_SCALE:
                raise ConfigError(
                    "", key, f"expected 0 or at least {MIN_REFERENCE_SCALE:g} in magnitude, got {value!r}"
                )

    def loaded(self, base_dir: Path | None = None, source: str = "") -> Reference:
        """This reference with its trajectory file read (kind ``file``; a relative ``path``
        resolves against ``base_dir``, the directory of the file naming it), else itself.
        Errors name ``reference.path`` in ``source``."""
        if self.kind != "file" or self.table is not None:
            return self
        p = Path(self.path)
        if not p.is_absolute() and base_dir is not None:
            p = base_dir / p
        p = p.absolute()
        return replace(self, path=str(p), table=load_reference_table(p, source))

    def sample(self, t_s: np.ndarray, base_dir: Path | None = None) -> np.ndarray:
        """x_d at the times ``t_s`` (m)."""
        if self.kind == "sine":
            return self.amplitude_m * np.sin(self.omega_rad_s * t_s)
        if self.kind == "step":
            return np.where(t_s >= self.start_s, self.amplitude_m, 0.0)
        if self.kind == "ramp":
            x = self.rate_m_s * np.maximum(t_s - self.start_s, 0.0)
            return np.clip(x, -self.amplitude_m, self.amplitude_m)
        if self.kind in ("square", "trapezoid"):
            return self._periodic(t_s)
        table = self.loaded(base_dir).table
        assert table is not None
        return table.sample(t_s)

    def _periodic(self, t_s: np.ndarray) -> np.ndarray:
        """Square or trapezoid wave (m), 0 before ``start_s``."""
        a = self.amplitude_m
        if self.omega_rad_s <= 0.0 or a <= 0.0:
            return np.zeros_like(t_s)
        tt = t_s - self.start_s
        phase = np.mod(tt * self.omega_rad_s / (2.0 * np.pi), 1.0)
        if self.kind == "square":
            x = np.where(phase < 0.5, a, -a)
        else:  # triangle of unit amplitude (0 → 1 → −1 → 0), scaled to the ramp rate, clipped
            tri = np.where(
                phase < 0.25, 4.0 * phase, np.where(phase < 0.75, 2.0 - 4.0 * phase, 4.0 * phase - 4.0)
            )
            peak_m = abs(self.rate_m_s) * np.pi / (2.0 * self.omega_rad_s)
            x = np.clip(peak_m * tri, -a, a)
        return np.where(tt >= 0.0, x, 0.0)

    @property
    def spool_amplitude_m(self) -> float:
        """Nominal spool amplitude this reference needs, r·ω/K_c with K_c of the default plant
        (:attr:`PlantParams.velocity_gain_1_s`, 3.288 1/s) (m).

        For steps and ramps (no ω) the rate-equivalent amplitude is used.
        """
        k_c = PlantParams().velocity_gain_1_s
        if self.kind == "sine":
            return self.amplitude_m * max(self.omega_rad_s, 1.0) / k_c
        if self.kind in ("ramp", "trapezoid"):
            return abs(self.rate_m_s) / k_c
        return self.amplitude_m * 5.0 / k_c


class ReferenceBlocks:
    """x_d sampled in blocks of ``block`` samples (m): cheap per cycle, no per-cycle arrays.

    A file reference is read here at the latest (before any loop starts; loaders read it when
    the config is loaded), then sampled from its table in memory.
    """

    def __init__(self, reference: Reference, ts_s: float, block: int = 1000) -> None:
        reference = reference.loaded()
        self.reference = reference
        self.ts_s = ts_s
        self._block = block
        self._k0 = 0
        self._buf = reference.sample(np.arange(block) * ts_s)

    def at(self, k: int) -> float:
        """x_d at sample k ≥ the previous k (m)."""
        if not self._k0 <= k < self._k0 + self._block:
            self._k0 = k
            self._buf = self.reference.sample((k + np.arange(self._block)) * self.ts_s)
        return float(self._buf[k - self._k0])


@dataclass(frozen=True)
class Noise:
    """Standard deviations of white measurement noise (SI units)."""

    position_m: float = field(default=0.0, metadata=rng(0.0, 0.01))
    spool_m: float = field(default=0.0, metadata=rng(0.0, 0.001))
    pressure_pa: float = field(default=0.0, metadata=rng(0.0, 1e7))


@dataclass(frozen=True)
class Disturbance:
    """``ω(t) = offset + amplitude·sin(omega·t)`` from ``start_s`` (the paper's case 4), in metres.

    ``enters: sensor`` subtracts it from the measured position, ``y_s = k_DFT·x − ω`` (the paper's
    G = B: the loop sees it exactly like an offset added to x_d, so an uncompensated loop moves
    the piston by ω); ``enters: valve`` adds ``ω·K_f·K_a·K_p`` amperes to the applied coil
    current (a load-like disturbance the PI integrates away).
    """

    kind: Literal["none", "offset_sine"] = "offset_sine"
    offset_m: float = field(default=0.0, metadata=rng(-0.1, 0.1))
    amplitude_m: float = field(default=0.0, metadata=rng(0.0, 0.1))
    omega_rad_s: float = field(default=10.0, metadata=rng(0.0, 2000.0))
    start_s: float = field(default=0.0, metadata=rng(0.0))
    enters: Literal["sensor", "valve"] = "sensor"

    def value_m(self, t_s: float) -> float:
        """ω(t) (m); 0 before ``start_s``."""
        if self.kind == "none" or t_s < self.start_s:
            return 0.0
        return self.offset_m + self.amplitude_m * math.sin(self.omega_rad_s * t_s)


@dataclass(frozen=True, slots=True)
class FrameLoss:
    """Loss probability per frame and direction: ``sensor`` (SENSOR_POS + SENSOR_AUX of a
    sample, one draw) and ``command`` (VALVE_CMD).

    ``frame_loss`` sets both directions; ``sensor_frame_loss`` / ``command_frame_loss`` then
    override one of them (in a scenario's top level and in each event alike: an event's
    ``frame_loss`` sets both again, a directional key changes only its direction).
    """

    sensor: float = 0.0
    command: float = 0.0

    def updated(self, both: float | None, sensor: float | None, command: float | None) -> FrameLoss:
        """This loss with the given keys applied (None = key not set)."""
        s = self.sensor if both is None else both
        c = self.command if both is None else both
        return FrameLoss(s if sensor is None else sensor, c if command is None else command)


@dataclass(frozen=True)
class Event:
    """A fault change at ``t_s``; every value given persists until changed by a later event."""

    t_s: float = field(metadata=rng(0.0))
    k_loe: float | None = field(default=None, metadata=rng(0.0, 1.5, lo_open=True))
    k_q: float | None = field(default=None, metadata=rng(0.0, 1.5, lo_open=True))
    k_dft: float | None = field(default=None, metadata=rng(0.0, 2.5))
    position_bias_m: float | None = field(default=None, metadata=rng(-0.1, 0.1))
    stuck: bool | None = None
    current_limit_a: float | None = field(default=None, metadata=rng(0.0, 1.0, lo_open=True))
    frame_loss: float | None = field(default=None, metadata=rng(0.0, 1.0))
    sensor_frame_loss: float | None = field(default=None, metadata=rng(0.0, 1.0))
    command_frame_loss: float | None = field(default=None, metadata=rng(0.0, 1.0))
    #: a fault of the valve electronics with this EMCY error code (protocol cia408: the valve
    #: goes to FAULT and sends EMCY; other protocols ignore it)
    device_fault: int | None = field(default=None, metadata=rng(0x1000, 0xFFFF))

    def __post_init__(self) -> None:
        if all(getattr(self, k) is None for k in _EVENT_KEYS):
            raise ConfigError("", "", "an event must set at least one of " + ", ".join(_EVENT_KEYS))

    def apply(self, faults: FaultState) -> FaultState:
        """The fault state after this event."""
        changes = {k: getattr(self, k) for k in _FAULT_KEYS if getattr(self, k) is not None}
        return replace(faults, **changes)

    def apply_loss(self, loss: FrameLoss) -> FrameLoss:
        """The per-direction loss after this event (see :class:`FrameLoss`)."""
        return loss.updated(self.frame_loss, self.sensor_frame_loss, self.command_frame_loss)


_FAULT_KEYS = ("k_loe", "k_q", "k_dft", "position_bias_m", "stuck", "current_limit_a")
_LOSS_KEYS = ("frame_loss", "sensor_frame_loss", "command_frame_loss")
_EVENT_KEYS = (*_FAULT_KEYS, *_LOSS_KEYS, "device_fault")


@dataclass(frozen=True)
class Scenario:
    """One test scenario (docs/design.md §10). Times in s, lengths in m.

    Frame loss (probability per frame): ``frame_loss`` for both directions, optionally
    overridden per direction by ``sensor_frame_loss`` / ``command_frame_loss`` (:class:`FrameLoss`).
    """

    name: str
    duration_s: float = field(metadata=rng(0.0, 86400.0, lo_open=True))
    sample_time_s: float = field(default=0.001, metadata=rng(1.0 / MAX_RATE_HZ, 1.0 / MIN_RATE_HZ))
    seed: int = field(default=1, metadata=rng(0, 2**32 - 1))
    reference: Reference = field(default_factory=Reference)
    noise: Noise = field(default_factory=Noise)
    frame_loss: float = field(default=0.0, metadata=rng(0.0, 1.0))
    #: overrides of ``frame_loss`` for one direction (None: ``frame_loss``), see FrameLoss
    sensor_frame_loss: float | None = field(default=None, metadata=rng(0.0, 1.0))
    command_frame_loss: float | None = field(default=None, metadata=rng(0.0, 1.0))
    transport_delay_samples: int = field(default=1, metadata=rng(0, 100))
    disturbance: Disturbance = field(default_factory=lambda: Disturbance(kind="none"))
    events: tuple[Event, ...] = ()
    description: str = ""
    #: the emulated plant's own parameters (plant ≠ model; the controller keeps its params)
    plant: PlantSpec = field(default_factory=PlantSpec)
    #: directory of the file it came from (for relative trajectory paths); not a YAML key
    base_dir: str = field(default="", metadata={"internal": True})

    def __post_init__(self) -> None:
        for i in range(1, len(self.events)):
            if self.events[i].t_s < self.events[i - 1].t_s:
                raise ConfigError(
                    "",
                    f"events[{i}].t_s",
                    f"events must be in time order ({self.events[i].t_s} < {self.events[i - 1].t_s})",
                )
        for i, ev in enumerate(self.events):
            if ev.t_s > self.duration_s:
                raise ConfigError(
                    "", f"events[{i}].t_s", f"event after the end of the run ({ev.t_s} > {self.duration_s})"
                )
        self._check_modelled_faults()

    def _check_modelled_faults(self) -> None:
        """An actuator fault the plant does not model (an FMU whose ``fmu_map`` does not name
        it) is refused: the bench cannot emulate it around the FMU."""
        modelled = self.plant.modelled_faults
        for i, ev in enumerate(self.events):
            for key in ACTUATOR_FAULTS:
                value = getattr(ev, key)
                if value is not None and value != 1.0 and key not in modelled:
                    raise ConfigError(
                        "",
                        f"events[{i}].{key}",
                        f"the FMU plant does not model {key}: map its input as plant.fmu_map.{key}",
                    )

    @property
    def n_samples(self) -> int:
        """Number of samples in the run."""
        return round(self.duration_s / self.sample_time_s)

    @property
    def initial_loss(self) -> FrameLoss:
        """The per-direction frame loss at k = 0."""
        return FrameLoss().updated(self.frame_loss, self.sensor_frame_loss, self.command_frame_loss)

    def fault_timeline(self) -> list[tuple[int, FaultState, FrameLoss]]:
        """``(sample index, fault state, frame loss per direction)`` at the start and at every
        event."""
        faults, loss = FaultState(), self.initial_loss
        out: list[tuple[int, FaultState, FrameLoss]] = [(0, faults, loss)]
        for ev in self.events:
            faults = ev.apply(faults)
            loss = ev.apply_loss(loss)
            out.append((round(ev.t_s / self.sample_time_s), faults, loss))
        return out

    def device_faults(self) -> list[tuple[int, int]]:
        """``(sample index, EMCY error code)`` of each ``device_fault`` event, in time order."""
        return [
            (round(ev.t_s / self.sample_time_s), ev.device_fault)
            for ev in self.events
            if ev.device_fault is not None
        ]

    def reference_samples(self) -> np.ndarray:
        """x_d at every sample (m)."""
        t = np.arange(self.n_samples) * self.sample_time_s
        return self.reference.sample(t, Path(self.base_dir) if self.base_dir else None)


def load_scenario(path: str | Path, data: object = None) -> Scenario:
    """Load and validate a scenario YAML file (``data``: its parsed content, when the caller
    read it already). At most :data:`~ehpss_hil.limits.MAX_SCENARIO_SAMPLES` samples, at least
    one; a file reference is read now, relative to the scenario's directory."""
    p = Path(path)
    sc = build(Scenario, load_yaml(p) if data is None else data, str(p))
    n = sc.duration_s / sc.sample_time_s
    if not 1 <= round(n) <= MAX_SCENARIO_SAMPLES:
        raise ConfigError(
            str(p),
            "duration_s",
            f"must hold 1 to {MAX_SCENARIO_SAMPLES} samples of sample_time_s, got {n:.6g}",
        )
    base = p.resolve().parent
    return replace(
        sc,
        base_dir=str(base),
        reference=sc.reference.loaded(base, str(p)),
        plant=sc.plant.loaded(base, str(p)),
    )
