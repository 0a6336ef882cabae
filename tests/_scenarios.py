"""Short scenarios for process tests (the shipped ones last 3 s): the paper's 1 mm, 5 rad/s sine
with the shipped sensor noise and one sample of transport delay."""

from __future__ import annotations


def short_scenario_yaml(name: str, duration_s: float, event: str, seed: int = 3) -> str:
    """Scenario YAML text with one event line, e.g. ``{t_s: 0.3, k_loe: 0.5}``."""
    return f"""\
name: {name}
duration_s: {duration_s}
sample_time_s: 0.001
seed: {seed}
reference: {{kind: sine, amplitude_m: 0.001, omega_rad_s: 5.0}}
noise: {{position_m: 1.0e-6, spool_m: 1.52e-6, pressure_pa: 1.0e4}}
transport_delay_samples: 1
events:
  - {event}
"""
