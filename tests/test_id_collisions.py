"""ID collisions (issue #16 item 5): a frame received on a process's own TX IDs that it did not
send is another transmitter's — counted per ID by :class:`FrameIO`, on buses that hand a process
its own frames back (a ring of the frames sent) and on those that never do. Real python-can
``virtual`` buses, in-process; nothing is timed."""

from __future__ import annotations

import random
from collections.abc import Iterator
from typing import Any

import can
import pytest
from _virtual import VirtualPair

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.config import SetpointPolicy, Watchdog
from ehpss_hil.control.base import Controller, ControllerStatus, Measurement, ValveCommand
from ehpss_hil.physics.load import load_params
from ehpss_hil.physics.params import Params
from ehpss_hil.protocol.failsafe import FailsafeReason
from ehpss_hil.runtime.collisions import SentFrames
from ehpss_hil.runtime.controller_loop import OWN_FRAMES, ControllerLoop, LoopOptions
from ehpss_hil.runtime.foreign import SensorStreams
from ehpss_hil.runtime.frameio import FrameIO, limit_sensor_rate
from ehpss_hil.runtime.lifecycle import State
from ehpss_hil.runtime.loop_run import loop_summary
from ehpss_hil.scenario import Reference


def _io(channel: str, echo: bool) -> tuple[FrameIO, can.BusABC, can.BusABC]:
    bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=echo)
    peer = can.Bus(interface="virtual", channel=channel)
    return FrameIO(bus, FrameCodec(), OWN_FRAMES), bus, peer


def _exchange(io: FrameIO, peer: can.BusABC) -> list[int]:
    """The controller sends its frames, a second controller (its own counters) sends the same
    names, the emulator a sensor frame; returns the IDs the loop got."""
    other, emu = FrameCodec(), FrameCodec()
    for k in range(5):
        io.send("VALVE_CMD", {"CurrentSetpoint": 1e-3, "Enable": 1, "CycleCount": k})
        io.send("HEARTBEAT_CTRL", {"NmtState": 5})
        peer.send(other.encode("VALVE_CMD", {"CurrentSetpoint": 0.5, "Enable": 1, "CycleCount": 900 + k}))
        peer.send(emu.encode("SENSOR_POS", {"Position": 0.0, "Spool": 0.0}))
    peer.send(other.encode("CTRL_STATUS", {"State": 2}))
    return [m.arbitration_id for m in io.drain()]


def test_foreign_frames_on_own_ids_are_counted_on_a_bus_without_echoes() -> None:
    io, bus, peer = _io("coll-noecho", echo=False)
    try:
        assert io.echoes_suppressed  # virtual without receive_own_messages: never its own frames
        got = _exchange(io, peer)
        assert got == [io.codec.can_id("SENSOR_POS")] * 5  # own IDs are never the loop's
        assert io.collisions.by_name["VALVE_CMD"] == 5
        assert io.collisions.by_name["CTRL_STATUS"] == 1 and io.collisions.total == 6
        assert io.received == 11 and io.sent["VALVE_CMD"] == 5
    finally:
        bus.shutdown()
        peer.shutdown()


def test_echoes_are_told_from_foreign_frames_where_the_bus_loops_back() -> None:
    io, bus, peer = _io("coll-echo", echo=True)
    try:
        assert not io.echoes_suppressed
        got = _exchange(io, peer)
        assert got == [io.codec.can_id("SENSOR_POS")] * 5
        # our 10 echoes (5 VALVE_CMD, 5 identical heartbeats) are not collisions; theirs are
        assert io.collisions.by_name == {
            "VALVE_CMD": 5,
            "CTRL_STATUS": 1,
            "CTRL_INDEX": 0,
            "CTRL_STATS": 0,
            "HEARTBEAT_CTRL": 0,
        }
        assert io.received == 11
    finally:
        bus.shutdown()
        peer.shutdown()


def test_sent_frames_ring() -> None:
    ring = SentFrames(capacity=3)
    for d in (b"a", b"b", b"a"):
        ring.add(0x120, d)
    assert len(ring) == 3
    assert ring.take(0x120, bytearray(b"a")) and ring.take(0x120, b"a")  # twice sent, twice due
    assert not ring.take(0x120, b"a") and not ring.take(0x121, b"b")
    for d in (b"c", b"d", b"e"):  # b's echo was lost: forgotten once 3 newer frames are due
        ring.add(0x120, d)
    assert not ring.take(0x120, b"b") and len(ring) == 3


# ---- the controller's reaction ---------------------------------------------------------------


class HoldLaw(Controller):
    """A law that commands 1 mA whatever it measures (the loop's reaction is under test)."""

    mode = "nrc"

    def configure(self, params: Params, ts_s: float) -> None: ...

    def reset(self) -> None: ...

    def step(self, meas: Measurement) -> ValveCommand:
        return ValveCommand(current_a=1e-3, enable=True)

    def status(self) -> ControllerStatus:
        return ControllerStatus(mode=self.mode, index={0: 0.5}, theta={0: 1.0})


class Rig(VirtualPair):
    """The controller loop (with the daemon's rate check), the emulator's frames from the peer
    and a rogue transmitter with counters of its own."""

    def __init__(self, name: str, wd: Watchdog | None = None, setpoint: SetpointPolicy | None = None) -> None:
        super().__init__(name)
        self.tx, self.rogue = FrameCodec(), FrameCodec()
        codec = FrameCodec()
        limit_sensor_rate(codec, load_params().plant.piston_speed_max_m_s, 1e-3)
        self.loop = ControllerLoop(
            HoldLaw(),
            FrameIO(self.bus, codec, OWN_FRAMES),
            Reference(kind="step", amplitude_m=1e-3),
            LoopOptions(watchdog=wd or Watchdog(), setpoint=setpoint or SetpointPolicy()),
        )
        self.rogue_cycle = 40000

    def sensors(self, position_m: float = 0.0, conflict: int = 0) -> None:
        self.peer.send(self.tx.encode("SENSOR_POS", {"Position": position_m, "Spool": 0.0}))
        self.peer.send(self.tx.encode("SENSOR_AUX", {"CoilCurrent": 1e-3, "CommandConflict": conflict}))

    def rogue_command(self) -> None:
        self.rogue_cycle += 1
        self.peer.send(
            self.rogue.encode(
                "VALVE_CMD", {"CurrentSetpoint": 0.5, "Enable": 1, "CycleCount": self.rogue_cycle}
            )
        )

    def cycle(self) -> dict[str, Any]:
        """One cycle; its VALVE_CMD."""
        self.loop.poll_cycle()
        return self.newest()["VALVE_CMD"]

    @property
    def state(self) -> tuple[State, FailsafeReason]:
        return self.loop.life.state, self.loop.life.reason


@pytest.fixture
def rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    r = Rig(request.node.name)
    yield r
    r.close()


def _active(rig: Rig, n: int = 5) -> None:
    for _ in range(n):
        rig.sensors()
        rig.cycle()
    assert rig.state == (State.ACTIVE, FailsafeReason.NONE)


def test_a_foreign_valve_cmd_is_a_fault(rig: Rig) -> None:
    _active(rig)
    rig.rogue_command()
    rig.sensors()
    cmd = rig.cycle()
    assert rig.state == (State.FAULT, FailsafeReason.ID_COLLISION)
    assert cmd["Enable"] == 0 and cmd["CurrentSetpoint"] == 0.0
    s = loop_summary(rig.loop)
    assert s["id_collisions"]["VALVE_CMD"] == 1  # type: ignore[index]
    assert s["second_transmitter"]["episodes"] == 1  # type: ignore[index]
    for _ in range(100):  # latched without auto_recover, though the rogue has gone
        rig.sensors()
        rig.cycle()
    assert rig.state == (State.FAULT, FailsafeReason.ID_COLLISION)


def test_command_conflict_from_the_emulator_is_a_fault(rig: Rig) -> None:
    _active(rig)
    rig.sensors(conflict=1)
    assert rig.cycle()["Enable"] == 0
    assert rig.state == (State.FAULT, FailsafeReason.ID_COLLISION)
    assert rig.loop.guard.conflict_frames == 1


def test_on_collision_warn_counts_and_goes_on() -> None:
    rig = Rig("coll-warn", wd=Watchdog(on_collision="warn"))
    try:
        _active(rig)
        for _ in range(20):
            rig.rogue_command()
            rig.sensors(conflict=1)
            assert rig.cycle()["Enable"] == 1
        assert rig.state == (State.ACTIVE, FailsafeReason.NONE)
        assert rig.loop.io.collisions.by_name["VALVE_CMD"] == 20
        assert rig.loop.guard.episodes == 1 and rig.loop.guard.conflict_frames == 20
    finally:
        rig.close()


def test_auto_recover_after_the_collision_has_been_quiet() -> None:
    rig = Rig("coll-recover", wd=Watchdog(auto_recover=True, recovery_cycles=20))
    try:
        _active(rig)
        rig.rogue_command()
        rig.sensors()
        rig.cycle()
        assert rig.state == (State.FAULT, FailsafeReason.ID_COLLISION)
        for _ in range(19):
            rig.sensors()
            rig.cycle()
        assert rig.state[0] is State.FAULT
        rig.sensors()
        rig.cycle()
        assert rig.state == (State.ACTIVE, FailsafeReason.NONE)
    finally:
        rig.close()


def test_a_second_sensor_pos_stream_is_a_collision(rig: Rig) -> None:
    """A rogue SENSOR_POS (well-formed, its own E2E counter) beside the emulator's: half the
    frames fail the sequence check; its readings, 50 mm away, fail the rate check. (Here the
    sensor's frames all fail the sequence check: the watchdog trips first, PLAUSIBILITY, and the
    reason becomes ID_COLLISION once the pattern is clear.)"""
    _active(rig)
    for _ in range(7):  # the rogue's counter two ahead of the sensor's: its frames pass E2E
        rig.rogue.skip("SENSOR_POS")
    for _ in range(60):
        rig.sensors(0.0)
        rig.peer.send(rig.rogue.encode("SENSOR_POS", {"Position": 0.05, "Spool": 0.0}))
        rig.cycle()
        if rig.state[1] is FailsafeReason.ID_COLLISION:
            break
    assert rig.state == (State.FAULT, FailsafeReason.ID_COLLISION)
    g = rig.loop.guard
    assert g.sensor.conflicts == 1 and g.sensor.failures >= 40
    assert "SENSOR_POS" in g.last_cause
    # the rogue's readings that passed the counter check failed the rate check: none was used
    assert rig.loop.codec.counts_by_name["SENSOR_POS"][Verdict.OUT_OF_RANGE] >= 1
    assert rig.loop.meas.position_m == 0.0


def test_one_sensor_losing_frames_in_bursts_is_not_a_collision(rig: Rig) -> None:
    """A starved receiver or a lossy bus: every frame arrives after a gap of 5 to 12 samples,
    so every frame fails the sequence check (WRONG_SEQUENCE) — the pattern that made a single
    emulator under load look like two. One sensor delivers no more than one frame per period,
    so it is no second transmitter (the watchdog may trip on the E2E errors: not ID_COLLISION)."""
    _active(rig)
    r = random.Random(3)
    for _ in range(300):
        for _ in range(r.randint(4, 11)):  # samples lost on the way: the counter moves on
            rig.tx.skip("SENSOR_POS")
            rig.tx.skip("SENSOR_AUX")
        rig.sensors(0.0)
        rig.cycle()
        for _ in range(r.randint(0, 3)):  # periods without a frame
            rig.cycle()
    g = rig.loop.guard
    assert g.sensor.failures >= 150  # the sequence evidence alone would have been a conflict
    assert g.sensor.conflicts == 0 and g.episodes == 0
    assert rig.state[1] is not FailsafeReason.ID_COLLISION


def test_a_sensor_faster_than_the_loop_is_not_a_collision(rig: Rig) -> None:
    """Two frames of one sensor per cycle (a sensor at twice the control rate): more frames
    than periods, but one sequence."""
    _active(rig)
    for _ in range(200):
        rig.sensors(0.0)
        rig.sensors(0.0)
        rig.cycle()
    g = rig.loop.guard
    assert g.sensor.max_frames > 70 and g.sensor.failures == 0
    assert g.sensor.conflicts == 0 and rig.state == (State.ACTIVE, FailsafeReason.NONE)


def test_sensor_streams_evidence() -> None:
    """The two kinds of evidence, frame by frame (runtime/foreign.py)."""
    codec, other = FrameCodec(), FrameCodec()
    for _ in range(7):
        other.skip("SENSOR_POS")

    def frame(c: FrameCodec, pos: float) -> bytes:
        return bytes(c.encode("SENSOR_POS", {"Position": pos, "Spool": 0.0}).data)

    # two senders, one frame each per cycle, half the frames out of sequence: a conflict
    two = SensorStreams()
    for k in range(60):
        two.add(False, frame(codec, k * 1e-6), k)
        two.add(True, frame(other, 0.05), k)
    assert two.conflict and two.conflicts == 1
    # copies are not frames: one sensor that sends every frame five times, many REPEATED
    dup = SensorStreams()
    for k in range(200):
        f = frame(codec, k * 1e-6)
        for j in range(5):
            dup.add(j > 0, f, k)
    assert dup.rate.total == 40 and not dup.conflict
    # a backlog (frames of periods slept through) is not counted against the rate
    backlog = SensorStreams()
    for k in range(200):
        backlog.add(True, frame(codec, k * 1e-6), 500, countable=k < 10)
    assert backlog.rate.total == 10 and not backlog.conflict


def test_setpoint_only_when_enabled_and_within_limits() -> None:
    off = Rig("sp-off")
    on = Rig("sp-on", setpoint=SetpointPolicy(enabled=True, max_abs_m=0.01, max_step_m=0.002))
    try:
        for rig in (off, on):
            _active(rig)
        codec = {off: FrameCodec(), on: FrameCodec()}

        def setpoint(rig: Rig, override: int, pos: float) -> float | None:
            rig.peer.send(codec[rig].encode("SETPOINT", {"Override": override, "Position": pos}))
            rig.sensors()
            rig.cycle()
            return rig.loop.driver.override_m

        assert setpoint(off, 1, 0.001) is None and off.loop.setpoints.rejected == 1
        assert setpoint(on, 1, 0.002) == pytest.approx(0.002)  # x_d was 1 mm: a 1 mm step
        assert setpoint(on, 1, 0.0045) == pytest.approx(0.002)  # a 2.5 mm step: rejected
        assert setpoint(on, 1, 0.004) == pytest.approx(0.004)
        for pos in (0.006, 0.008, 0.010):
            assert setpoint(on, 1, pos) == pytest.approx(pos)
        assert setpoint(on, 1, 0.0115) == pytest.approx(0.010)  # beyond ±10 mm: rejected
        assert setpoint(on, 0, 0.0) is None  # back to the configured trajectory
        assert (on.loop.setpoints.accepted, on.loop.setpoints.rejected) == (6, 2)
        assert loop_summary(on.loop)["setpoints"] == {"accepted": 6, "rejected": 2}
    finally:
        off.close()
        on.close()
