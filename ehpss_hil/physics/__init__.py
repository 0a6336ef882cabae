"""EHPSS physics: parameters, continuous models, exact ZOH, reference model. Pure numpy."""

from .faults import FaultState
from .load import load_params
from .params import ControllerGains, Params, PlantParams

__all__ = ["ControllerGains", "FaultState", "Params", "PlantParams", "load_params"]
