"""The per-sample record of one lockstep run (SI units, one row per sample k)."""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
from numpy.typing import NDArray

Array = NDArray[np.float64]

#: number of model slots in CTRL_INDEX (columns of :attr:`SimResult.index`)
N_SLOTS = 16


@dataclass
class SimResult:
    """Arrays of one run. Lengths are ``n`` samples; ``index`` is ``n × 16`` (NaN: unused slot).

    ``t_s`` time (s); ``x_d_m`` reference; ``y_m_m`` reference-model output; ``x_true_m`` true piston
    position; ``y_s_m`` position sensor as sent by the emulator; ``spool_m`` spool LVDT as sent;
    ``current_a`` current applied over [k, k+1); ``active_spool``/``active_position`` model slots
    (−1: none); ``k_loe_hat``/``k_dft_hat`` estimates in use; ``true_k_loe``/``true_k_q``/
    ``true_k_dft`` fault values in force; ``fresh`` whether the sensor frame arrived;
    ``fallback`` whether the do-no-harm monitor held the loop on nominal compensation and
    ``stuck`` whether the position sensor was stuck (both empty for results that do not record
    them).
    """

    scenario: str
    controller: str
    ts_s: float
    event_times_s: tuple[float, ...]
    t_s: Array
    x_d_m: Array
    y_m_m: Array
    x_true_m: Array
    y_s_m: Array
    spool_m: Array
    current_a: Array
    active_spool: NDArray[np.int64]
    active_position: NDArray[np.int64]
    k_loe_hat: Array
    k_dft_hat: Array
    index: Array
    true_k_loe: Array
    true_k_q: Array
    true_k_dft: Array
    fresh: NDArray[np.bool_]
    wall_s: float = 0.0
    #: CPU time of this process spent in the loop (s): the "one core" cost on a shared machine
    cpu_s: float = 0.0
    frame_counts: dict[str, int] = field(default_factory=dict)
    fallback: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))
    #: the position sensor stuck (PLANT_TRUTH Stuck) per sample; empty when not recorded
    stuck: NDArray[np.bool_] = field(default_factory=lambda: np.zeros(0, dtype=bool))

    @property
    def error_m(self) -> Array:
        """e = x_true − y_m (m), the docs/design.md §10 tracking error."""
        return self.x_true_m - self.y_m_m

    @property
    def duration_s(self) -> float:
        """Simulated time (s)."""
        return len(self.t_s) * self.ts_s

    @property
    def speed(self) -> float:
        """Simulated seconds per second of CPU time of the loop on one core (0 when not timed).

        CPU time, not wall time: on a shared machine the wall clock also counts time the process
        waited for a core. :attr:`wall_speed` gives the wall-clock figure.
        """
        t = self.cpu_s if self.cpu_s > 0 else self.wall_s
        return self.duration_s / t if t > 0 else 0.0

    @property
    def wall_speed(self) -> float:
        """Simulated seconds per wall-clock second of the loop (0 when not timed)."""
        return self.duration_s / self.wall_s if self.wall_s > 0 else 0.0

    def arrays(self) -> dict[str, np.ndarray]:
        """Every per-sample array by name (for comparisons and saving)."""
        names = (
            "t_s",
            "x_d_m",
            "y_m_m",
            "x_true_m",
            "y_s_m",
            "spool_m",
            "current_a",
            "active_spool",
            "active_position",
            "k_loe_hat",
            "k_dft_hat",
            "index",
            "true_k_loe",
            "true_k_q",
            "true_k_dft",
            "fresh",
        )
        return {n: getattr(self, n) for n in names}
