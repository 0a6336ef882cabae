"""The controller's status on the bus: CTRL_STATUS and its CTRL_INDEX snapshot (DBC frames).

One :class:`StatusReporter` per controller loop: :meth:`StatusReporter.send` puts CTRL_STATUS
out now and queues one CTRL_INDEX per model slot (J and θ), which the loop sends one per
following cycle (or all at once), so that no cycle carries nine frames.
"""

from __future__ import annotations

import math

from ..control.base import Controller
from .frameio import FrameIO
from .lifecycle import Lifecycle

#: CTRL_STATUS ``Mode`` values
MODE_CODE = {"nrc": 0, "smac": 1, "mmac-paper": 2, "mmac": 3, "oracle": 4}
_F32_MAX = 3.0e38


class StatusReporter:
    """CTRL_STATUS + queued CTRL_INDEX frames of one controller."""

    def __init__(self, io: FrameIO) -> None:
        self.io = io
        #: (slot, J, θ) still to send, the next one last
        self.pending: list[tuple[int, float, float]] = []

    def send(self, controller: Controller, life: Lifecycle, all_index: bool = False) -> None:
        """``controller``'s CTRL_STATUS now; the CTRL_INDEX frames (one per model slot) queued,
        or all sent at once with ``all_index``."""
        s = controller.status()
        self.io.send("CTRL_STATUS", {
            "State": int(life.state), "FailsafeReason": int(life.reason),
            "Mode": MODE_CODE.get(controller.mode, 15),
            "ActiveSpoolModel": _nibble(s.active_model.get("spool", 0)),
            "ActivePosModel": _nibble(s.active_model.get("position", 0)),
            "KLoeHat": _clip(s.k_loe_hat, 0.0, 4.095), "KDftHat": _clip(s.k_dft_hat, 0.0, 4.095),
            "Switches": min(s.switches, 255)})
        self.pending = [(slot, j, s.theta.get(slot, 0.0))
                        for slot, j in reversed(s.index.items()) if 0 <= slot <= 15]
        while all_index and self.pending:
            self.send_next_index()

    def send_next_index(self) -> None:
        """The next queued CTRL_INDEX (J dimensionless, θ the model's gain)."""
        slot, j, theta = self.pending.pop()
        self.io.send("CTRL_INDEX", {"ModelSlot": slot, f"J_{slot}": _clip(j, -_F32_MAX, _F32_MAX),
                                    f"Theta_{slot}": _clip(theta, 0.0, 6.5535)})


def _clip(v: float, lo: float, hi: float) -> float:
    if not math.isfinite(v):
        return hi if v > 0 else lo
    return max(lo, min(hi, v))


def _nibble(v: int) -> int:
    return int(v) & 0x0F
