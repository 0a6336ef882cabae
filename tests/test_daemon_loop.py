"""The controller daemon's loop in-process over python-can ``virtual`` (the rig of
``_daemon_rig.py``: cycles are counted, nothing is timed): commands, fail-safe, recovery,
shutdown, caught-up periods, status frames. Lockstep: ``test_daemon_lockstep.py``."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import can
import pytest
from _daemon_rig import MiniPI, Rig, activate

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.codec.e2e import protect
from ehpss_hil.config import Watchdog
from ehpss_hil.control.base import ControllerStatus, Measurement, ValveCommand
from ehpss_hil.protocol.failsafe import FailsafeReason
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.lifecycle import State


@pytest.fixture
def rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    r = Rig(request.node.name)
    yield r
    r.close()


def test_configured_sends_zero_until_sensor_data(rig: Rig) -> None:
    for _ in range(10):  # no sensor data yet: no watchdog trip, zero current, disabled
        cmd = rig.cycle()["VALVE_CMD"]
        assert cmd["CurrentSetpoint"] == 0.0 and cmd["Enable"] == 0
    assert rig.loop.life.state is State.CONFIGURED
    rig.sensors()
    cmd = rig.cycle()["VALVE_CMD"]
    assert rig.loop.life.state is State.ACTIVE and cmd["Enable"] == 1


def test_one_command_per_cycle_echoes_the_sensor_counter(rig: Rig) -> None:
    activate(rig)
    sent = rig.loop.io.sent["VALVE_CMD"]
    for i in range(20):
        pos = rig.sensors(1e-4 * i)
        cmd = rig.cycle()["VALVE_CMD"]
        assert cmd["SensorCounterEcho"] == pos.data[1] & 0x0F
        assert cmd["CycleCount"] == rig.loop.cycles - 1
    assert rig.loop.io.sent["VALVE_CMD"] == sent + 20


def test_newest_of_several_frames_is_used(rig: Rig) -> None:
    activate(rig)
    rig.sensors(1e-3)
    newest = rig.sensors(2e-3)
    cmd = rig.cycle()["VALVE_CMD"]
    assert cmd["SensorCounterEcho"] == newest.data[1] & 0x0F
    assert rig.loop.meas.position_m == pytest.approx(2e-3)


def _cycles_to_failsafe(rig: Rig, feed: Any = None) -> int:
    for n in range(1, 20):
        if feed is not None:
            feed()
        cmd = rig.cycle()["VALVE_CMD"]
        if cmd["Enable"] == 0 and cmd["CurrentSetpoint"] == 0.0:
            return n
    return -1


def _status(rig: Rig) -> dict[str, Any]:
    rig.loop.send_status()
    m = rig.peer.recv(1.0)
    assert m is not None
    d = rig.rx.classify(m)
    assert d.name == "CTRL_STATUS" and d.values is not None
    return d.values


def test_sensor_timeout_failsafe_within_3_cycles(rig: Rig) -> None:
    activate(rig, 50)
    n = _cycles_to_failsafe(rig)
    assert 1 <= n <= 3, n
    assert rig.loop.life.state is State.FAULT
    st = _status(rig)
    assert st["State"] == int(State.FAULT) and st["FailsafeReason"] == int(FailsafeReason.SENSOR_TIMEOUT)


def test_e2e_errors_failsafe_with_reason(rig: Rig) -> None:
    activate(rig)
    pid = rig.tx.can_id("SENSOR_POS")

    def corrupt() -> None:
        data = bytearray(rig.tx.encode("SENSOR_POS", {"Position": 0.0, "Spool": 0.0}).data)
        data[0] ^= 0x5A
        rig.peer.send(can.Message(arbitration_id=pid, data=bytes(data), is_extended_id=False))

    assert _cycles_to_failsafe(rig, corrupt) <= 3
    assert rig.loop.life.reason is FailsafeReason.E2E_ERRORS


def test_implausible_data_failsafe_with_reason(rig: Rig) -> None:
    activate(rig)
    pid = rig.tx.can_id("SENSOR_POS")
    msg = rig.tx.message("SENSOR_POS")
    counter = [rig.tx._tx_counter["SENSOR_POS"]]  # continue the sequence: only the range is bad

    def implausible() -> None:
        raw = bytearray(msg.encode({"CRC": 0, "Counter": 0, "Position": 0.8, "Spool": 0.0}, strict=False))
        data = protect(raw, counter[0], rig.tx.data_ids("SENSOR_POS"))  # type: ignore[arg-type]
        counter[0] = (counter[0] + 1) & 0x0F
        rig.peer.send(can.Message(arbitration_id=pid, data=data, is_extended_id=False))

    assert _cycles_to_failsafe(rig, implausible) <= 3
    assert rig.loop.life.reason is FailsafeReason.PLAUSIBILITY


def test_failsafe_hold_keeps_last_command() -> None:
    r = Rig("hold", Watchdog(timeout_cycles=3, failsafe="hold"))
    try:
        for _ in range(20):
            r.sensors(-1e-3)
            r.cycle()
        cmds = [r.cycle()["VALVE_CMD"] for _ in range(6)]
        assert r.loop.life.state is State.FAULT
        held = [(c["CurrentSetpoint"], c["Enable"]) for c in cmds[-3:]]
        assert held[0] == held[1] == held[2] and held[0][1] == 1 and held[0][0] != 0.0
    finally:
        r.close()


def test_auto_recovery_after_m_fresh_cycles() -> None:
    r = Rig("recover", Watchdog(timeout_cycles=3, recovery_cycles=10, auto_recover=True))
    try:
        activate(r)
        for _ in range(3):
            r.cycle()
        assert r.loop.life.state is State.FAULT
        states: list[State] = []
        for _ in range(12):
            r.sensors()
            r.cycle()
            states.append(r.loop.life.state)
        assert states.index(State.ACTIVE) == 9  # the 10th fresh cycle
    finally:
        r.close()


def test_shutdown_sends_zero_disabled_and_stopped(rig: Rig) -> None:
    activate(rig)
    rig.loop.shutdown()
    got = rig.newest()
    assert got["VALVE_CMD"]["CurrentSetpoint"] == 0.0 and got["VALVE_CMD"]["Enable"] == 0
    assert got["CTRL_STATUS"]["State"] == int(State.STOPPED)
    assert got["HEARTBEAT_CTRL"]["NmtState"] == 4


def test_skipped_periods_are_stepped_without_frames() -> None:
    """An overrun that skipped 3 grid periods (fewer than the watchdog's 10 and than the
    predictors bridge): the law steps 3 more times without data (fresh False) and without
    sending (command_sent False), the reference index moves on by 4, one VALVE_CMD goes out with
    CycleCount 4 on; the watchdog counted them as cycles without data (and the fresh cycle
    after them ended the streak)."""
    rig = Rig("skipped", Watchdog(timeout_cycles=10))
    try:
        _check_skipped_steps(rig)
    finally:
        rig.close()


def _check_skipped_steps(rig: Rig) -> None:
    activate(rig, 20)
    seen: list[tuple[bool, bool]] = []
    orig = rig.ctrl.step

    def step(meas: Measurement) -> ValveCommand:
        seen.append((meas.fresh, meas.command_sent))
        return orig(meas)

    rig.ctrl.step = step  # type: ignore[method-assign]
    rig.sensors()
    c0 = rig.cycle()["VALVE_CMD"]["CycleCount"]
    k0, sent0, steps0 = rig.loop.k_active, rig.loop.io.sent["VALVE_CMD"], rig.ctrl.steps
    seen.clear()
    rig.sensors(5e-4)
    rig.loop.poll_cycle(skipped=3)
    cmds = rig.values_of("VALVE_CMD")
    assert len(cmds) == 1 and rig.loop.io.sent["VALVE_CMD"] == sent0 + 1
    assert cmds[0]["CycleCount"] == c0 + 4
    # the caught-up steps know their command is not sent (the valve holds the previous one)
    assert rig.ctrl.steps == steps0 + 4 and seen == [(False, False)] * 3 + [(True, True)]
    assert rig.loop.k_active == k0 + 4 and rig.loop.skipped_periods == 3
    assert rig.loop.life.state is State.ACTIVE and rig.loop.wd.trips == 0
    assert rig.loop.wd.lateness.late == 3 and rig.loop.wd.stale_cycles == 0
    assert rig.loop.meas.position_m == pytest.approx(5e-4)  # the frame is used after the catch-up


class IndexedPI(MiniPI):
    """MiniPI reporting nine model slots (like mmac: 4 spool + 5 position)."""

    def status(self) -> ControllerStatus:
        return ControllerStatus(
            mode=self.mode, index={s: 0.1 * s for s in range(9)}, theta={s: 1.0 for s in range(9)}
        )


def test_status_frames_one_per_cycle_at_their_rates() -> None:
    """CTRL_STATUS (50 Hz), CTRL_STATS and heartbeat (10 Hz) and the nine CTRL_INDEX of each
    snapshot: never two in one cycle, none lost, the index frames in slot order."""
    r = Rig("periodic")
    r.ctrl = IndexedPI()
    r.loop.controller = r.ctrl  # type: ignore[assignment]
    periodic = ("CTRL_STATUS", "CTRL_INDEX", "CTRL_STATS", "HEARTBEAT_CTRL")
    try:
        activate(r)
        while r.loop.cycles % 100:  # count from just after a cycle with all three due
            r.sensors()
            r.cycle()
        per_cycle: list[list[str]] = []
        slots: list[int] = []
        for _ in range(1000):
            r.sensors()
            r.loop.poll_cycle()
            names = []
            for _, d in r.received():
                if d.name in periodic and d.values is not None:
                    names.append(d.name)
                    if d.name == "CTRL_INDEX":
                        slots.append(d.values["ModelSlot"])
            per_cycle.append(names)
        assert max(len(n) for n in per_cycle) == 1
        count = {p: sum(n.count(p) for n in per_cycle) for p in periodic}
        assert count == {"CTRL_STATUS": 50, "CTRL_INDEX": 450, "CTRL_STATS": 10, "HEARTBEAT_CTRL": 10}
        assert slots[:18] == [*range(9), *range(9)]
    finally:
        r.close()


def test_send_together_encodes_first_and_keeps_order() -> None:
    """The emulator's sensor pair: both frames leave in order; a frame that cannot be encoded
    is a counted transmit error and does not stop the others."""
    tx = can.Bus(interface="virtual", channel="together")
    rx = can.Bus(interface="virtual", channel="together")
    try:
        io = FrameIO(tx, FrameCodec(), ("SENSOR_POS", "SENSOR_AUX"))
        n = io.send_together(
            ("SENSOR_POS", {"Position": 1e-3, "Spool": 2e-6}),
            ("SENSOR_AUX", {"LoadPressure": float("nan")}),  # not encodable
            ("SENSOR_AUX", {"LoadPressure": 1e5, "CoilCurrent": 0.01}),
        )
        assert n == 2 and io.tx_errors == 1
        assert io.sent == {"SENSOR_POS": 1, "SENSOR_AUX": 1}
        codec = FrameCodec()
        got = [codec.classify(m) for m in iter(lambda: rx.recv(0.1), None)]
        assert [d.name for d in got] == ["SENSOR_POS", "SENSOR_AUX"]
        assert all(d.verdict is Verdict.OK for d in got)
        assert got[0].values is not None and abs(got[0].values["Position"] - 1e-3) < 1e-7
        assert got[1].values is not None and abs(got[1].values["LoadPressure"] - 1e5) < 10
    finally:
        tx.shutdown()
        rx.shutdown()
