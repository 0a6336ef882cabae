"""The one list of controller modes and the factory :func:`make_controller`.

Each mode has its class, its CTRL_STATUS ``Mode`` code (DBC value table) and whether the daemon
may run it (``oracle`` needs the true faults: simulator only). Every other list of modes (the
configuration's choices, the command line's, the status frame's codes) is taken from here.
"""

from __future__ import annotations

from dataclasses import dataclass

from ..errors import ModelError
from ..physics.params import Params
from .adaptive import MmacController
from .base import NominalMotion
from .controllers import LoopBase, NrcController, OracleController
from .joint import JointController
from .tuning import ControlTuning


@dataclass(frozen=True)
class ModeSpec:
    """One controller mode: its class, DBC ``Mode`` code and whether the daemon runs it."""

    cls: type[LoopBase]
    code: int
    daemon: bool = True


#: mode name → spec, in the order the tables print them
REGISTRY: dict[str, ModeSpec] = {
    "nrc": ModeSpec(NrcController, 0),
    "smac": ModeSpec(JointController, 1),
    "mmac-paper": ModeSpec(JointController, 2),
    "mmac": ModeSpec(MmacController, 3),
    "oracle": ModeSpec(OracleController, 4, daemon=False),
}
MODES = tuple(REGISTRY)
DAEMON_MODES = tuple(m for m, s in REGISTRY.items() if s.daemon)
#: CTRL_STATUS ``Mode`` code per mode
MODE_CODE = {m: s.code for m, s in REGISTRY.items()}


def make_controller(
    mode: str,
    params: Params,
    ts_s: float,
    tuning: ControlTuning | None = None,
    reference: NominalMotion | None = None,
) -> LoopBase:
    """Build and configure the controller for ``mode`` (one of :data:`MODES`).

    ``reference`` (a scenario's Reference, or any :class:`NominalMotion`) sets the channels'
    nominal amplitudes S (default: the paper's 1 mm, 5 rad/s sine).
    """
    spec = REGISTRY.get(mode)
    if spec is None:
        raise ModelError(f"unknown controller mode {mode!r}; choose one of {', '.join(MODES)}")
    tun = tuning if tuning is not None else ControlTuning()
    cls = spec.cls
    ctrl = cls(tun, reference, mode) if cls is JointController else cls(tun, reference)
    ctrl.configure(params, ts_s)
    return ctrl
