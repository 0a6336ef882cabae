"""The frame layer of a lockstep run under ``protocol: cia408``: the master's codec on the
controller's side, the same PDO layouts encoded on the emulator's side.

Per sample: the master's SYNC (counted), the two TPDOs answering it in the nodes' order — the
valve's (status word, spool actual value), then the encoder's (position value) — classified by
the controller's :class:`~ehpss_hil.protocol.cia408.codec.Cia408Codec` in that order, as they
arrive on a bus; the command is the valve's RPDO 1 (control word + set-point), decoded on the
emulator's side to the current the valve applies. The valve is taken as ACTIVE from the first
sample (the master's start-up, which a lockstep run leaves out, put it there). The echo of
the applied current and the missing load pressure are the codec's (its module docstring).
"""

from __future__ import annotations

from ..driver import ControllerDriver
from ..protocol.cia408.codec import Cia408Codec
from ..protocol.cia408.drive import REQUEST
from ..protocol.cia408.objects import STATUS_OF, DeviceState
from .transport import _clip, applied_current, take_sensor_pair

#: the largest |position| (m) and |spool| (m) the sensors report (the native DBC's ranges)
POSITION_RANGE_M = 0.5
SPOOL_RANGE_M = 0.01


class Cia408Transport:
    """Real CANopen PDO bytes between the emulator's side and the master's codec."""

    def __init__(self, emu_codec: Cia408Codec, ctrl_codec: Cia408Codec) -> None:
        self._emu = emu_codec
        self._ctrl = ctrl_codec
        ctrl_codec.control_word = REQUEST[DeviceState.ACTIVE]
        self._status = STATUS_OF[DeviceState.ACTIVE]
        self.syncs = 0

    def sensor(
        self,
        drv: ControllerDriver,
        k: int,
        pos: float,
        spool: float,
        pressure: float,
        coil: float,
        saturated: bool,
        lost: bool,
    ) -> bool:
        """SYNC, then the valve's and the encoder's TPDO, classified by the master's codec and
        handed to ``drv`` (position, spool, load pressure, current echo as the master decodes
        them: m, m, Pa, A); False when ``lost`` (``k``: the sample, carried by the SYNC count)."""
        self._ctrl.encode("SYNC", {"Cycle": self.syncs})
        self.syncs += 1
        valve = self._emu.encode(
            "SENSOR_AUX", {"Spool": _clip(spool, SPOOL_RANGE_M), "StatusWord": self._status}
        )
        encoder = self._emu.encode("SENSOR_POS", {"Position": _clip(pos, POSITION_RANGE_M)})
        if lost:
            return False
        d_aux = self._ctrl.classify(valve)  # first: the encoder's SENSOR_POS carries its spool
        return take_sensor_pair(drv, self._ctrl.classify(encoder), d_aux)

    def command(self, current_a: float, k: int, lost: bool) -> float | None:
        """The valve's RPDO 1 from the master; the current the valve applies (A), None if ``lost``."""
        f = self._ctrl.encode("VALVE_CMD", {"CurrentSetpoint": current_a, "Enable": 1})
        return None if lost else applied_current(self._emu.classify(f))

    def counts(self) -> dict[str, int]:
        """Verdict counts of both receivers (name → count) and the SYNCs sent."""
        out: dict[str, int] = {"SYNC": self.syncs}
        for c in (self._emu, self._ctrl):
            for v, n in c.counts.items():
                out[v.name] = out.get(v.name, 0) + n
        return out
