"""A second VALVE_CMD transmitter beside a real controller and emulator on the embedded bus
(private network namespace, real processes): the emulator centres the valve and flags
CommandConflict, the controller counts the collision and goes to fail-safe ID_COLLISION, the
piston never leaves x_d by more than 1 mm. Nothing is timed."""

from __future__ import annotations

from pathlib import Path

import pytest

from ehpss_hil.reliability.procs import skip_reason
from ehpss_hil.reliability.rogue import MAX_DEVIATION_M, rogue_trial

SKIP = skip_reason()
pytestmark = pytest.mark.skipif(SKIP is not None, reason=SKIP or "")


def test_rogue_commander_at_1khz(tmp_path: Path) -> None:
    res = rogue_trial(tmp_path, rogue_s=1.0, duration_s=3.0)
    assert not res.error, res.line()
    assert res.sent > 0
    assert res.emulator["command_conflicts"] >= 1 and res.command_conflict_seen, res.line()
    assert res.controller["failsafe_reason"] == "ID_COLLISION", res.line()
    assert res.valve_cmd_collisions > 0
    assert res.controller["second_transmitter"]["episodes"] >= 1
    assert res.truth_samples > 0 and res.max_deviation_m <= MAX_DEVIATION_M, res.line()
    assert res.exits == {"emulator": 0, "controller": 0}
    assert res.ok
    log = (tmp_path / "controller.out").read_text()
    assert "ID collision: VALVE_CMD" in log and "ID_COLLISION" in log
    assert log.count("WARNING: cycle") <= 2  # warned once per episode, not per frame
