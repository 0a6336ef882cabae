"""EHPSS physics: parameters, continuous models, exact ZOH, reference model. Pure numpy."""

from .faults import FaultState
from .params import ControllerGains, Params, PlantParams, load_params

__all__ = ["ControllerGains", "FaultState", "Params", "PlantParams", "load_params"]
