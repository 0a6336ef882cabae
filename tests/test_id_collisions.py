"""ID collisions (issue #16 item 5): a frame received on a process's own TX IDs that it did not
send is another transmitter's — counted per ID by :class:`FrameIO`, on buses that hand a process
its own frames back (a ring of the frames sent) and on those that never do. Real python-can
``virtual`` buses, in-process; nothing is timed."""

from __future__ import annotations

import can

from ehpss_hil.codec import FrameCodec
from ehpss_hil.runtime.collisions import SentFrames
from ehpss_hil.runtime.controller_loop import OWN_FRAMES
from ehpss_hil.runtime.frameio import FrameIO


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
        peer.send(other.encode("VALVE_CMD", {"CurrentSetpoint": 0.5, "Enable": 1,
                                             "CycleCount": 900 + k}))
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
        assert io.collisions.by_name == {"VALVE_CMD": 5, "CTRL_STATUS": 1, "CTRL_INDEX": 0,
                                         "CTRL_STATS": 0, "HEARTBEAT_CTRL": 0}
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
