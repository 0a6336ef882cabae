"""The controller daemon's loop in-process over python-can ``virtual``: cycles are counted,
nothing is timed. A minimal PI (this file only) keeps the loop tests independent of the control
law; one test runs the real ``mmac`` law against the emulator in lockstep."""

from __future__ import annotations

import threading
from collections.abc import Iterator
from typing import Any

import can
import pytest
from _virtual import VirtualPair

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.codec.e2e import protect
from ehpss_hil.config import Watchdog
from ehpss_hil.control.base import Controller, ControllerStatus, Measurement, ValveCommand
from ehpss_hil.physics.params import Params, load_params
from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.runtime.lifecycle import FailsafeReason, State
from ehpss_hil.runtime.signals import StopFlag
from ehpss_hil.scenario import Reference, Scenario


class MiniPI(Controller):
    """A tiny PI on the position error (A per m), enough to exercise the loop."""

    mode = "nrc"

    def __init__(self, kp: float = 0.05, ki: float = 0.5, ts_s: float = 1e-3) -> None:
        self.kp, self.ki, self.ts_s = kp, ki, ts_s
        self.z = 0.0
        self.steps = 0

    def configure(self, params: Params, ts_s: float) -> None:
        self.ts_s = ts_s

    def reset(self) -> None:
        self.z = 0.0

    def step(self, meas: Measurement) -> ValveCommand:
        e = meas.reference_m - meas.position_m
        self.z += self.ts_s * e
        self.steps += 1
        return ValveCommand(current_a=self.kp * e + self.ki * self.z, enable=True)

    def status(self) -> ControllerStatus:
        return ControllerStatus(mode=self.mode, index={0: 0.5}, theta={0: 1.0})


class Rig(VirtualPair):
    """Controller loop + a test peer playing the emulator on one virtual channel."""

    def __init__(self, name: str, wd: Watchdog | None = None) -> None:
        super().__init__(name)
        self.tx = FrameCodec()
        self.ctrl = MiniPI()
        self.loop = ControllerLoop(
            self.ctrl,
            FrameIO(self.bus, FrameCodec(), OWN_FRAMES),
            Reference(kind="step", amplitude_m=1e-3),
            LoopOptions(watchdog=wd or Watchdog()),
        )

    def sensors(self, position_m: float = 0.0) -> can.Message:
        pos = self.tx.encode("SENSOR_POS", {"Position": position_m, "Spool": 0.0})
        self.peer.send(pos)
        self.peer.send(self.tx.encode("SENSOR_AUX", {"CoilCurrent": 1e-5}))
        return pos

    def cycle(self) -> dict[str, dict[str, Any]]:
        """One loop cycle; returns the newest decoded frame of each name the loop sent."""
        self.loop.poll_cycle()
        return self.newest()

    def cycle_with(self, position_m: float) -> dict[str, Any]:
        """Sensor frames, then one cycle; returns its VALVE_CMD."""
        self.sensors(position_m)
        return self.cycle()["VALVE_CMD"]


@pytest.fixture
def rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    r = Rig(request.node.name)
    yield r
    r.close()


def _activate(rig: Rig, n: int = 5) -> None:
    for _ in range(n):
        rig.sensors()
        rig.cycle()
    assert rig.loop.life.state is State.ACTIVE


def test_configured_sends_zero_until_sensor_data(rig: Rig) -> None:
    for _ in range(10):  # no sensor data yet: no watchdog trip, zero current, disabled
        cmd = rig.cycle()["VALVE_CMD"]
        assert cmd["CurrentSetpoint"] == 0.0 and cmd["Enable"] == 0
    assert rig.loop.life.state is State.CONFIGURED
    rig.sensors()
    cmd = rig.cycle()["VALVE_CMD"]
    assert rig.loop.life.state is State.ACTIVE and cmd["Enable"] == 1


def test_one_command_per_cycle_echoes_the_sensor_counter(rig: Rig) -> None:
    _activate(rig)
    sent = rig.loop.io.sent["VALVE_CMD"]
    for i in range(20):
        pos = rig.sensors(1e-4 * i)
        cmd = rig.cycle()["VALVE_CMD"]
        assert cmd["SensorCounterEcho"] == pos.data[1] & 0x0F
        assert cmd["CycleCount"] == rig.loop.cycles - 1
    assert rig.loop.io.sent["VALVE_CMD"] == sent + 20


def test_newest_of_several_frames_is_used(rig: Rig) -> None:
    _activate(rig)
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
    _activate(rig, 50)
    n = _cycles_to_failsafe(rig)
    assert 1 <= n <= 3, n
    assert rig.loop.life.state is State.FAULT
    st = _status(rig)
    assert st["State"] == int(State.FAULT) and st["FailsafeReason"] == int(FailsafeReason.SENSOR_TIMEOUT)


def test_e2e_errors_failsafe_with_reason(rig: Rig) -> None:
    _activate(rig)
    pid = rig.tx.can_id("SENSOR_POS")

    def corrupt() -> None:
        data = bytearray(rig.tx.encode("SENSOR_POS", {"Position": 0.0, "Spool": 0.0}).data)
        data[0] ^= 0x5A
        rig.peer.send(can.Message(arbitration_id=pid, data=bytes(data), is_extended_id=False))

    assert _cycles_to_failsafe(rig, corrupt) <= 3
    assert rig.loop.life.reason is FailsafeReason.E2E_ERRORS


def test_implausible_data_failsafe_with_reason(rig: Rig) -> None:
    _activate(rig)
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
        _activate(r)
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
    _activate(rig)
    rig.loop.shutdown()
    got = rig.newest()
    assert got["VALVE_CMD"]["CurrentSetpoint"] == 0.0 and got["VALVE_CMD"]["Enable"] == 0
    assert got["CTRL_STATUS"]["State"] == int(State.STOPPED)
    assert got["HEARTBEAT_CTRL"]["NmtState"] == 4


def test_lockstep_with_emulator_and_mmac() -> None:
    """The real control law against the emulator, both in lockstep: one answer per sample."""
    from ehpss_hil.control.registry import make_controller
    from ehpss_hil.emulation import PlantEmulation
    from firmware_sim.process import OWN_FRAMES as EMU_FRAMES
    from firmware_sim.process import EmulatorOptions, EmulatorProcess

    sc = Scenario(name="ls", duration_s=0.5)
    params = load_params()
    eb = can.Bus(interface="virtual", channel="daemon-lockstep")
    cb = can.Bus(interface="virtual", channel="daemon-lockstep")
    try:
        emu = EmulatorProcess(
            PlantEmulation(params, sc), FrameIO(eb, FrameCodec(), EMU_FRAMES), EmulatorOptions()
        )
        loop = ControllerLoop(
            make_controller("mmac", params, 1e-3, None, sc.reference),
            FrameIO(cb, FrameCodec(), OWN_FRAMES),
            sc.reference,
            LoopOptions(lockstep_idle_s=0.5),
        )
        th = threading.Thread(target=loop.run_lockstep, args=(StopFlag(), sc.n_samples))
        th.start()
        assert emu.run_lockstep(StopFlag(), sc.n_samples)
        th.join()
        assert loop.cycles == sc.n_samples == emu.hold.accepted
        assert loop.life.state is State.ACTIVE and emu.hold.timeouts == 0
        assert abs(emu.emu.plant.position_m) < 2e-3
    finally:
        eb.shutdown()
        cb.shutdown()


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
    _activate(rig, 20)
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
        _activate(r)
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


def _lockstep_run(rig: Rig, feed: Any) -> list[dict[str, Any]]:
    """Run the lockstep loop until the bus is idle for 0.3 s while ``feed()`` sends frames;
    returns the VALVE_CMDs it answered with."""
    loop = ControllerLoop(
        rig.ctrl, rig.loop.io, Reference(kind="step", amplitude_m=1e-3), LoopOptions(lockstep_idle_s=0.3)
    )
    rig.loop = loop
    th = threading.Thread(target=loop.run_lockstep, args=(StopFlag(),))
    th.start()
    feed()
    th.join(timeout=30)
    assert not th.is_alive()
    return rig.values_of("VALVE_CMD")


def test_lockstep_answers_a_duplicate_pair_never(rig: Rig) -> None:
    """A repeated sensor pair (same bytes) is counted REPEATED and gets no cycle: the law steps
    and answers once per distinct pair."""

    def feed() -> None:
        for i in range(3):
            pos = rig.sensors(1e-4 * i)
            if i == 1:
                rig.peer.send(pos)  # the same frames again
                rig.peer.send(rig.tx.encode("SENSOR_AUX", {"CoilCurrent": 1e-5}, counter=1))

    cmds = _lockstep_run(rig, feed)
    assert len(cmds) == 3 and rig.ctrl.steps == 3
    assert [c["CycleCount"] for c in cmds] == [0, 1, 2]
    assert rig.loop.codec.counts_by_name["SENSOR_POS"][Verdict.REPEATED] == 1


def test_lockstep_steps_over_lost_sensor_samples(rig: Rig) -> None:
    """Two sensor samples lost on the way (the counter jumps by 3): the law steps twice without
    data before the cycle, so the reference stays on the plant's sample clock."""

    def feed() -> None:
        rig.sensors()
        rig.sensors()
        for _ in range(2):
            rig.tx.skip("SENSOR_POS")
            rig.tx.skip("SENSOR_AUX")
        rig.sensors(3e-4)

    cmds = _lockstep_run(rig, feed)
    assert len(cmds) == 3 and rig.ctrl.steps == 5
    assert [c["CycleCount"] for c in cmds] == [0, 1, 4]
    assert rig.loop.k_active == 5 and rig.loop.skipped_periods == 2


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
