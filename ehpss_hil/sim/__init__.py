"""Deterministic lockstep simulation: emulated plant + frame layer + controller, one process."""

from .lockstep import TRANSPORTS, run_scenario
from .result import SimResult

__all__ = ["TRANSPORTS", "SimResult", "run_scenario"]
