"""The controller as the CANopen master (``configs/controller-cia408.yaml``) and the emulated
CiA 408 valve + CiA 406 encoder (``configs/emulator-cia408.yaml``) as two real processes under
``ehpss-hil run`` on the embedded bus, realtime, in a private network namespace: start-up by SDO
and NMT, SYNC from the controller's loop, tracking on the encoder's position value, the stop
sequence; an injected device fault (the emulator's EMCY) puts the controller into fail-safe with
reason EMCY in CTRL_STATUS and the EMCY code in CTRL_DEVICE. Tracking is judged only when both
processes kept time (their summaries say so); nothing is timed."""

from __future__ import annotations

import json
import math
import struct
import warnings
from pathlib import Path

import can
import numpy as np
import pytest
from _proc import STARTUP_LIMIT_S

from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.canlog import read_log
from ehpss_hil.codec import FrameCodec
from ehpss_hil.orchestrate import RunPlan, check_exit_codes, execute
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol.cia408 import cobid
from ehpss_hil.protocol.failsafe import FailsafeReason
from ehpss_hil.runtime.lifecycle import State
from ehpss_hil.sim.lockstep import reference_output

NETNS_SKIP = netns_unavailable_reason()
pytestmark = [
    pytest.mark.netns,
    pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}"),
]

ROOT = Path(__file__).resolve().parent.parent
VALVE, ENCODER = 32, 33
#: the mmac bound of the native realtime tests (tests/test_protocol_processes.py)
RMS_BOUND_M = 15e-6
#: RPDOs (cycles) from the EMCY to the first one asking for DISABLED: the cycle that drains it
#: sends it, or the next one when the EMCY came during a cycle
FAILSAFE_CYCLES = 2
TS_S, AMPLITUDE_M, OMEGA = 0.001, 0.001, 5.0


def _scenario(path: Path, duration_s: float, events: str) -> Path:
    path.write_text(
        f"name: {path.stem}\nduration_s: {duration_s}\nsample_time_s: {TS_S}\nseed: 3\n"
        f"reference: {{kind: sine, amplitude_m: {AMPLITUDE_M}, omega_rad_s: {OMEGA}}}\n"
        "noise: {position_m: 1.0e-6, spool_m: 1.52e-6, pressure_pa: 1.0e4}\n"
        f"transport_delay_samples: 1\nevents: {events}\n"
    )
    return path


def _run(tmp_path: Path, scenario: Path) -> tuple[Path, dict, dict]:
    out = tmp_path / "run"
    plan = RunPlan(
        scenario_path=scenario,
        mode="mmac",
        out_dir=out,
        controller_yaml=ROOT / "configs" / "controller-cia408.yaml",
        emulator_yaml=ROOT / "configs" / "emulator-cia408.yaml",
        truth=False,
        startup_timeout_s=STARTUP_LIMIT_S,
    )
    check_exit_codes(execute(plan))
    ctl = json.loads((out / "controller-summary.json").read_text())
    emu = json.loads((out / "emulator-summary.json").read_text())
    return out, ctl, emu


def _kept_time(ctl: dict, emu: dict) -> bool:
    return not (ctl["skipped_periods"] or emu["skipped_periods"] or ctl["stale_frames"])


def _tracking_rms_m(log: Path) -> tuple[float, int]:
    """RMS of the encoder's position (TPDO answering SYNC s) against the reference model's y_m
    at sample s − s0, s0 the SYNCs sent before the first ACTIVE set-point (the controller's
    first step); and the samples it covers."""
    syncs, s0, rows = 0, None, []
    for m in read_log(log):
        fid = m.arbitration_id
        if fid == cobid.SYNC:
            syncs += 1
        elif fid == cobid.RPDO1 + VALVE and s0 is None:
            word, setpoint = struct.unpack("<Hh", bytes(m.data))
            s0 = syncs if word == 0x0007 and setpoint else None
        elif fid == cobid.TPDO1 + ENCODER and s0 is not None:
            rows.append((syncs - s0, struct.unpack("<i", bytes(m.data))[0] * 1e-7))
    assert rows, "no position value after the first ACTIVE set-point"
    n = max(k for k, _ in rows) + 1
    y_m = reference_output(load_params(), TS_S, AMPLITUDE_M * np.sin(OMEGA * TS_S * np.arange(n)))
    err = [p - y_m[k] for k, p in rows if k >= 0]
    return math.sqrt(sum(e * e for e in err) / len(err)), len(err)


@pytest.mark.alone
def test_realtime_cia408_master_starts_the_nodes_tracks_and_stops(tmp_path: Path) -> None:
    out, ctl, emu = _run(tmp_path, _scenario(tmp_path / "cia408-ff.yaml", 1.5, "[]"))
    assert "first sensor data: ACTIVE" in (out / "controller.out").read_text()
    log = list(read_log(out / "bus.log"))
    services = {cobid.classify(m.arbitration_id)[0] for m in log}
    assert {"NMT", "SYNC", "SDO_RX", "SDO_TX", "TPDO1", "RPDO1", "HEARTBEAT"} <= services
    nmt = [bytes(m.data) for m in log if m.arbitration_id == cobid.NMT]
    start, stop = [bytes([1, VALVE]), bytes([1, ENCODER])], [bytes([2, VALVE]), bytes([2, ENCODER])]
    if ctl["cia408"]["shut_out"]:  # a starved master lost a heartbeat and shut the valve out
        # (SDO DISABLED, NMT Stop of the valve) before its own stop: one more Stop of the valve
        assert nmt == [*start, bytes([2, VALVE]), *stop], nmt
        warnings.warn(f"the master shut the valve out ({ctl['failsafe_reason']})", stacklevel=1)
    else:
        assert nmt == [*start, *stop], nmt
    # the start-up's SDO writes reached the valve: its set-point RPDO timer and heartbeat consumer
    assert emu["nodes"]["ValveNode:32"]["sdo_requests"] >= 14 and emu["nodes"]["ValveNode:32"]["rpdos"] > 0
    assert ctl["frames_sent"]["SYNC"] == ctl["frames_sent"]["VALVE_CMD"] - 1  # one per cycle
    assert emu["syncs"] > 0 and emu["nodes"]["EncoderNode:33"]["tpdos"] == emu["syncs"]
    rpdos = [struct.unpack("<Hh", bytes(m.data)) for m in log if m.arbitration_id == cobid.RPDO1 + VALVE]
    assert rpdos[-1] == (0x0001, 0)  # stop: DISABLED with set-point 0, before the NMT stop
    rms, n = _tracking_rms_m(out / "bus.log")
    if not _kept_time(ctl, emu):  # a starved master may let the valve's set-point timeout fire
        warnings.warn(
            f"cia408 realtime run did not keep time: RMS {rms * 1e6:.1f} um not judged", stacklevel=1
        )
        return
    assert ctl["cia408"]["emcy_frames"] == 0
    assert n > 1000 and rms < RMS_BOUND_M, (rms, n)


def _active_setpoint(m: can.Message) -> bool:
    """An RPDO asking for ACTIVE with a set-point: the controller steps."""
    if m.arbitration_id != cobid.RPDO1 + VALVE:
        return False
    word, setpoint = struct.unpack("<Hh", bytes(m.data))
    return word == 0x0007 and setpoint != 0


@pytest.mark.alone
def test_realtime_emcy_puts_the_controller_into_failsafe_with_its_reason(tmp_path: Path) -> None:
    sc = _scenario(tmp_path / "cia408-emcy.yaml", 2.0, "[{t_s: 1.5, device_fault: 0x5000}]")
    out, ctl, _ = _run(tmp_path, sc)
    log = list(read_log(out / "bus.log"))
    at = next(i for i, m in enumerate(log) if m.arbitration_id == cobid.EMCY + VALVE)
    if struct.unpack_from("<H", bytes(log[at].data))[0] != 0x5000:  # a starved master first
        warnings.warn(
            f"the valve's first EMCY is 0x{struct.unpack_from('<H', bytes(log[at].data))[0]:04X} (the "
            "set-point timeout of a starved master), not the device fault: not judged",
            stacklevel=1,
        )
        return
    if not any(_active_setpoint(m) for m in log[:at]):  # plant time runs from the emulator's start
        warnings.warn(
            "the device fault came before the valve was ACTIVE (slow start-up): not judged", stacklevel=1
        )
        return
    assert ctl["failsafe_reason"] == "EMCY"
    assert ctl["cia408"]["emcy"] == {"node": VALVE, "code": 0x5000, "register": 1}
    after = [bytes(m.data) for m in log[at:] if m.arbitration_id == cobid.RPDO1 + VALVE]
    n = next(i for i, d in enumerate(after, start=1) if struct.unpack("<Hh", d) == (0x0001, 0))
    assert n <= FAILSAFE_CYCLES, n
    codec = FrameCodec()
    status = [codec.classify(m).values for m in log[at:] if m.arbitration_id == codec.can_id("CTRL_STATUS")]
    first_fault = next(v for v in status if v is not None and v["State"] == State.FAULT)
    assert first_fault["FailsafeReason"] == FailsafeReason.EMCY
    device = [codec.classify(m).values for m in log[at:] if m.arbitration_id == codec.can_id("CTRL_DEVICE")]
    assert device and device[0] is not None
    assert (device[0]["EmcyNode"], device[0]["EmcyCode"], device[0]["ErrorRegister"]) == (VALVE, 0x5000, 1)
