"""Deterministic lockstep simulation: emulated plant + frame layer + controller, one process."""

from ..report.result import SimResult
from .lockstep import TRANSPORTS, run_scenario

__all__ = ["TRANSPORTS", "SimResult", "run_scenario"]
