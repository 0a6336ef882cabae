"""The rogue CANopen node of tests/test_cia408_rogue_processes.py on SocketCAN (issue #29): the
controller (CiA 408 master), the emulated valve and the rogue as real processes on vcan0; the
rogue sends the valve's RPDO at +100 %. Run where vcan0 exists, else by ``.ci/run`` / ``make
test-socketcan`` inside ../shared/tools/vcan-vm/run, where Python is ~10× slower: one trial,
with the slow-host settings (:data:`~ehpss_hil.reliability.rogue_cia408.SLOW_HOST`: loops at
50 Hz, the nodes' timeouts beyond the VM's stalls). Nothing is timed, so the piston's
deviation (bounded on the host by tests/test_cia408_rogue_processes.py) is not judged here."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest
from _vcan import vcan_reason

from ehpss_hil.reliability.rogue_cia408 import (
    CASES,
    MAX_FAILSAFE_CYCLES,
    SLOW_HOST,
    VALVE,
    rogue_cia408_trial,
)

pytestmark = pytest.mark.socketcan
#: how long the rogue sends (s); the emulator runs until the valve is shut out (slow=True)
ROGUE_S = 0.5


@pytest.fixture
def vcan0() -> str:
    reason = vcan_reason()
    if reason is not None:
        pytest.skip(reason)
    return "vcan0"


def test_a_rogue_rpdo_on_vcan0_is_shut_out(vcan0: str, tmp_path: Path) -> None:
    res = rogue_cia408_trial(tmp_path, "rpdo", ROGUE_S, socketcan=vcan0, slow=True)
    assert not res.error and res.sent > 0, res.line()
    # PLANT_TRUTH from the emulator: at least a second of it (at SLOW_HOST's rate)
    assert res.source == "truth" and res.samples > SLOW_HOST["rate_hz"], res.line()
    assert res.exits == {"emulator": 0, "controller": 0}, res.line()
    emu_cfg = (tmp_path / "emulator.yaml").read_text()
    assert "interface: socketcan" in emu_cfg and "channel: vcan0" in emu_cfg  # not the embedded bus
    if res.preempted:  # a starved loop: the master disabled the valve before the rogue
        warnings.warn(
            f"the master disabled the valve before the rogue: not judged: {res.line()}", stacklevel=1
        )
        return
    assert res.reason == CASES["rpdo"].reason == "ID_COLLISION", res.line()
    assert res.failsafe_cycles is not None and res.failsafe_cycles <= MAX_FAILSAFE_CYCLES, res.line()
    assert res.controller["cia408"]["shut_out"] is True, res.line()
    assert res.emulator["nodes"][f"ValveNode:{VALVE}"]["nmt"] == "STOPPED", res.line()
    assert res.emulator["valve_state"] in ("DISABLED", "FAULT_HOLD"), res.line()
    # the piston: |x − x_d| is the rogue's +100 % integrated over the master's reaction in wall
    # time, which the VM does not keep (MAX_DEVIATION_M is judged on the host): only finite here
    assert res.max_deviation_m < float("inf"), res.line()
    out = (tmp_path / "controller.out").read_text()
    assert f"valve {VALVE} shut out" in out and "on socketcan:vcan0" in out, out[-2000:]
