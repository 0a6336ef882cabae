"""A rogue CANopen node beside the CiA 408 master and the emulated valve, as real processes on
the embedded bus in a private network namespace (issue #29 item 1): the rogue sends the valve's
RPDO at +100 %, one NMT Stop of the valve, a second SYNC, an RPDO or a TPDO shorter than
mapped. Each is judged on its outcome: the controller's fail-safe reason (its summary), the
controller cycles from the rogue's first frame to its first RPDO asking for DISABLED (its log),
the piston's deviation from x_d (PLANT_TRUTH in the emulator's log) and the valve's state.
Nothing is timed."""

from __future__ import annotations

import warnings
from pathlib import Path

import pytest

from ehpss_hil.reliability.procs import skip_reason
from ehpss_hil.reliability.rogue_cia408 import (
    CASES,
    MAX_DEVIATION_M,
    MAX_FAILSAFE_CYCLES,
    VALVE,
    rogue_cia408_trial,
)

SKIP = skip_reason()
pytestmark = [pytest.mark.netns, pytest.mark.alone, pytest.mark.skipif(SKIP is not None, reason=SKIP or "")]


@pytest.mark.parametrize("case", sorted(CASES))
def test_a_rogue_canopen_node_is_shut_out(tmp_path: Path, case: str) -> None:
    res = rogue_cia408_trial(tmp_path, case, rogue_s=0.5, duration_s=5.0)
    assert not res.error and res.sent > 0, res.line()
    assert res.source == "truth" and res.samples > 1000, res.line()
    assert res.max_deviation_m <= MAX_DEVIATION_M, res.line()
    assert res.exits == {"emulator": 0, "controller": 0}, res.line()
    if res.preempted:  # a starved loop: the valve's set-point timeout (EMCY) came first
        warnings.warn(
            f"the master disabled the valve before the rogue: not judged: {res.line()}", stacklevel=1
        )
        return
    assert res.reason == CASES[case].reason, res.line()
    assert res.failsafe_cycles is not None and res.failsafe_cycles <= MAX_FAILSAFE_CYCLES, res.line()
    assert res.controller["cia408"]["shut_out"] is True, res.line()
    # the master's NMT Stop reached the valve: no PDO of the rogue is processed any more
    assert res.emulator["nodes"][f"ValveNode:{VALVE}"]["nmt"] == "STOPPED", res.line()
    assert res.emulator["valve_state"] in ("DISABLED", "FAULT_HOLD"), res.line()
    assert res.ok, res.line()
    out = (tmp_path / "controller.out").read_text()
    assert f"valve {VALVE} shut out" in out and CASES[case].reason in out, out[-2000:]
