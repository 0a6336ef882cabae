"""The CiA 408 emulator when its plant fails (an FMU's step: the test FMU failing from t = 1 s):
the valve does what a real valve does on an internal fault — FAULT with EMCY 0x6100 in its status
word and on the bus, 0 A, a fault a reset cannot clear — while the nodes keep running, and the
emulator exits 1 with ``plant_failure`` in its summary. Checked with ``canopen``'s own master on a
python-can virtual bus, and with the controller as CANopen master in real processes under
``ehpss-hil run`` (its fail-safe, reason EMCY; a plant failed at power-on outlasts the master's
fault resets: DEVICE_FAULT). Nothing is timed."""

from __future__ import annotations

import json
import struct
import warnings
from itertools import pairwise
from pathlib import Path

import can
import pytest

pytest.importorskip("fmpy")
pytest.importorskip("pythonfmu")

from _cia408 import Cia408Rig, emcy_codes, heartbeat_state, wait_until
from _fmu import scenario
from _proc import STARTUP_LIMIT_S

from ehpss_hil.bench.fmu import fmu_spec
from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.canlog import read_log
from ehpss_hil.orchestrate import RunPlan, execute
from ehpss_hil.physics.fmutest import TEST_FMU_MAP, build_test_fmu
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.cia408.objects import (
    BIT_D,
    BIT_H,
    BIT_M,
    BIT_R,
    EMCY_INTERNAL_SOFTWARE,
    EMCY_NO_ERROR,
    ERR_REG_GENERIC,
    DeviceState,
    state_of_status,
)
from ehpss_hil.scenario import Scenario

ROOT = Path(__file__).resolve().parent.parent
VALVE, ENCODER = 32, 33
#: the test FMU's step fails from this plant time on (s)
FAIL_AT_S = 1.0
#: the message of its first failed step
FAILED_STEP = "fmi2DoStep returned Discard (step at t = 1.0000 s)"
#: RPDOs (cycles) from the EMCY to the first one asking for DISABLED (tests/test_cia408_master_processes.py)
FAILSAFE_CYCLES = 2
NETNS_SKIP = netns_unavailable_reason()


@pytest.fixture(scope="module")
def failing_fmu(tmp_path_factory: pytest.TempPathFactory) -> Path:
    return build_test_fmu(tmp_path_factory.mktemp("fmu"), fail_at_s=FAIL_AT_S)


def _run(tmp_path: Path, fmu: Path) -> tuple[Path, dict[str, int | None], dict, dict]:
    """``ehpss-hil run`` (realtime, CiA 408 configs, 2 s) with ``fmu`` as the emulator's plant:
    the run folder, the exit codes, the emulator's and the controller's summaries."""
    sc = scenario(tmp_path / "sc", fmu, events=[], duration_s=2.0)
    out = tmp_path / "run"
    plan = RunPlan(
        scenario_path=sc,
        mode="mmac",
        out_dir=out,
        controller_yaml=ROOT / "configs" / "controller-cia408.yaml",
        emulator_yaml=ROOT / "configs" / "emulator-cia408.yaml",
        truth=False,
        startup_timeout_s=STARTUP_LIMIT_S,
    )
    res = execute(plan)
    assert res.unfinished_after_s is None
    emu = json.loads((out / "emulator-summary.json").read_text())
    ctl = json.loads((out / "controller-summary.json").read_text())
    return out, res.exit_codes, emu, ctl


def _codes(log: list[can.Message], node: int) -> list[int]:
    """The EMCY codes ``node`` sent, in order."""
    return [struct.unpack_from("<H", bytes(m.data))[0] for m in log if m.arbitration_id == cobid.EMCY + node]


def _active_setpoint(m: can.Message) -> bool:
    """An RPDO asking for ACTIVE with a set-point: the controller steps."""
    if m.arbitration_id != cobid.RPDO1 + VALVE:
        return False
    word, setpoint = struct.unpack("<Hh", bytes(m.data))
    return word == BIT_D | BIT_H | BIT_M and setpoint != 0


def _sync(r: Cia408Rig) -> tuple[int, int]:
    """SYNC → (valve status word, encoder position value) from the TPDOs it triggers."""
    for pdo in (r.valve.tpdo[1], r.encoder.tpdo[1]):
        pdo.is_received = False
    r.net.sync.transmit()
    assert wait_until(lambda: r.valve.tpdo[1].is_received and r.encoder.tpdo[1].is_received)
    return r.valve.tpdo[1][0].raw, r.encoder.tpdo[1][0].raw


def test_the_valve_latches_an_internal_fault_a_reset_cannot_clear(failing_fmu: Path) -> None:
    """canopen's master: EMCY 0x6100 (register generic) and the error history, status word
    FAULT, 0 A; the encoder still answers SYNC with the position the piston holds; a fault reset
    (rising R) is answered by EMCY 0 and at once by FAULT with a new EMCY 0x6100."""
    sc = Scenario(name="fmu-fail", duration_s=3600.0, plant=fmu_spec(failing_fmu, TEST_FMU_MAP))
    rig = Cia408Rig(
        {"interface": "virtual", "receive_own_messages": False, "channel": "cia408-plant"}, scenario=sc
    )
    with rig as r:
        v = r.valve
        for n in (v, r.encoder):
            n.nmt.state = "OPERATIONAL"
            assert heartbeat_state(n, "OPERATIONAL") == "OPERATIONAL"
            n.tpdo.read(from_od=True)
        v.rpdo.read(from_od=True)
        assert wait_until(lambda: EMCY_INTERNAL_SOFTWARE in emcy_codes(v), 60.0)
        emcy = next(e for e in v.emcy.log if e.code == EMCY_INTERNAL_SOFTWARE)
        assert emcy.register == ERR_REG_GENERIC
        assert FAILED_STEP in r.proc.plant_failure
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.FAULT)
        status, position = _sync(r)
        assert state_of_status(status) == DeviceState.FAULT
        assert _sync(r)[1] == position  # the plant no longer advances: the piston holds
        assert v.sdo[0x1003][1].raw & 0xFFFF == EMCY_INTERNAL_SOFTWARE
        v.rpdo[1][0].raw = BIT_D | BIT_H | BIT_M  # asking for ACTIVE: refused in FAULT
        v.rpdo[1][1].raw = 3277
        v.rpdo[1].transmit()
        assert state_of_status(_sync(r)[0]) == DeviceState.FAULT and r.proc.valve.current_a() == 0.0
        before = emcy_codes(v).count(EMCY_INTERNAL_SOFTWARE)
        v.rpdo[1][0].raw = BIT_R  # rising edge of R: fault reset
        v.rpdo[1].transmit()
        assert wait_until(lambda: emcy_codes(v).count(EMCY_INTERNAL_SOFTWARE) > before)
        assert EMCY_NO_ERROR in emcy_codes(v)[-2:]  # the reset's "no error", then the fault again
        assert wait_until(lambda: r.proc.valve.device.state == DeviceState.FAULT)
        assert state_of_status(_sync(r)[0]) == DeviceState.FAULT
    s = r.proc.summary()
    assert s["valve_state"] == "FAULT" and FAILED_STEP in s["plant_failure"]
    assert s["periods"] > FAIL_AT_S * 1000  # the nodes ran on after the plant stopped


@pytest.mark.alone
@pytest.mark.netns
@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_realtime_the_controller_fails_safe_when_the_emulated_plant_fails(
    failing_fmu: Path, tmp_path: Path
) -> None:
    """``ehpss-hil run`` with the CiA 408 configs and the failing FMU as the emulator's plant:
    the emulator logs one error line, keeps its nodes up to the end of the run and exits 1
    (``plant_failure``, valve FAULT); on the bus the valve's EMCY 0x6100 and FAULT status words;
    the controller fails safe with reason EMCY and asks for DISABLED within two cycles."""
    out, codes, emu, ctl = _run(tmp_path, failing_fmu)
    assert codes["emulator"] == 1 and codes["controller"] == 0, codes
    assert FAILED_STEP in emu["plant_failure"] and emu["valve_state"] == "FAULT"
    assert emu["periods"] == 2000  # the nodes ran to the end of the run
    errors = [ln for ln in (out / "emulator.out").read_text().splitlines() if ": ERROR: " in ln]
    assert len(errors) == 1 and "plant stopped, valve 32 in FAULT" in errors[0], errors
    assert "Traceback" not in (out / "emulator.out").read_text()
    log = list(read_log(out / "bus.log"))
    at = next(
        i
        for i, m in enumerate(log)
        if m.arbitration_id == cobid.EMCY + VALVE
        and struct.unpack_from("<H", bytes(m.data))[0] == EMCY_INTERNAL_SOFTWARE
    )
    status = [
        struct.unpack_from("<H", bytes(m.data))[0]
        for m in log[at:]
        if m.arbitration_id == cobid.TPDO1 + VALVE
    ]
    assert status and state_of_status(status[-1]) == DeviceState.FAULT
    assert ctl["cia408"]["emcy"] == {"node": VALVE, "code": EMCY_INTERNAL_SOFTWARE, "register": 1}
    if _codes(log, VALVE)[0] != EMCY_INTERNAL_SOFTWARE:  # a starved master
        warnings.warn(
            "the valve faulted before its plant failed (a starved master): not judged", stacklevel=1
        )
        return
    if not any(_active_setpoint(m) for m in log[:at]):  # a slow start-up: the fault met while enabling
        # the master's drive resets it (at most 3 times); the valve faults again after each reset
        assert ctl["cia408"]["fault_reason"] == "DEVICE_FAULT" and ctl["cia408"]["fault_resets"] == 3, ctl
        warnings.warn("the plant failed before the valve was ACTIVE (slow start-up)", stacklevel=1)
        return
    assert ctl["failsafe_reason"] == "EMCY"
    after = [struct.unpack("<Hh", bytes(m.data)) for m in log[at:] if m.arbitration_id == cobid.RPDO1 + VALVE]
    n = next(i for i, d in enumerate(after, start=1) if d == (BIT_D, 0))
    assert n <= FAILSAFE_CYCLES, n


@pytest.mark.alone
@pytest.mark.netns
@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_realtime_a_plant_failed_at_power_on_outlasts_the_masters_fault_resets(tmp_path: Path) -> None:
    """The plant fails 20 ms after the emulator's start, before any master can enable the
    valve: the controller's drive meets FAULT while enabling and resets it three times; each
    reset (EMCY 0) is followed by FAULT again (EMCY 0x6100), so the master gives up with
    DEVICE_FAULT — the valve never drives the plant."""
    fmu = build_test_fmu(tmp_path / "fmu", fail_at_s=0.02)
    out, codes, emu, ctl = _run(tmp_path, fmu)
    assert codes["emulator"] == 1 and codes["controller"] == 0, codes
    assert "(step at t = 0.0200 s)" in emu["plant_failure"] and emu["valve_state"] == "FAULT"
    assert ctl["cia408"]["fault_reason"] == "DEVICE_FAULT" and ctl["cia408"]["fault_resets"] == 3, ctl
    assert ctl["cia408"]["error_history"]["codes"][:3] == [EMCY_INTERNAL_SOFTWARE] * 3
    log = list(read_log(out / "bus.log"))
    emcy = _codes(log, VALVE)  # a reset edge met in FAULT_REACTION is not taken: no EMCY 0 for it
    assert set(emcy) == {EMCY_INTERNAL_SOFTWARE, EMCY_NO_ERROR} and emcy[-1] == EMCY_INTERNAL_SOFTWARE, emcy
    assert all(nxt == EMCY_INTERNAL_SOFTWARE for c, nxt in pairwise(emcy) if c == EMCY_NO_ERROR)
    assert not any(_active_setpoint(m) for m in log)
