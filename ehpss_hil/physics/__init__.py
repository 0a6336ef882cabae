"""EHPSS physics: parameters, continuous models, exact ZOH, reference model. Pure numpy/scipy."""

from .params import ControllerGains, Params, PlantParams, load_params
from .faults import FaultState

__all__ = ["ControllerGains", "FaultState", "Params", "PlantParams", "load_params"]
