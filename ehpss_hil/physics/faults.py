"""The plant's fault state (dimensionless gains and sensor extras)."""

from __future__ import annotations

from dataclasses import dataclass


@dataclass(frozen=True)
class FaultState:
    """Fault values acting on the plant at one instant.

    k_loe: spool-side loss of effectiveness (actual spool = k_loe × commanded spool), 1 = healthy.
    k_q: flow-gain factor downstream of the spool (not seen by the spool LVDT), 1 = healthy.
    k_dft: position sensor gain (eq 11), 1 = healthy, 0 = failed sensor.
    position_bias_m: additive position sensor bias (m).
    stuck: the position sensor output freezes at its last value.
    current_limit_a: valve amplifier saturation (A).
    """

    k_loe: float = 1.0
    k_q: float = 1.0
    k_dft: float = 1.0
    position_bias_m: float = 0.0
    stuck: bool = False
    current_limit_a: float = 1.0

    @property
    def dynamics_key(self) -> tuple[float, float]:
        """The values that change the plant's continuous dynamics (ZOH cache key)."""
        return (self.k_loe, self.k_q)
