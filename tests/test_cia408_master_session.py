"""The controller's start-up as the CANopen master (:class:`MasterSession`) against the emulated
nodes (firmware-sim's CANopen loop in a thread, one virtual bus): what it writes by SDO lands in
the nodes' objects, both go OPERATIONAL, the encoder's measuring step reaches the codec, no
library thread is left; then NMT stop."""

from __future__ import annotations

import threading
from dataclasses import replace

import can
import pytest
from _cia408 import Cia408Rig, wait_until

from ehpss_hil.config import CanIds, Cia408Config
from ehpss_hil.errors import NodeError
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol import make_codec
from ehpss_hil.protocol.cia408.codec import Cia408Codec
from ehpss_hil.protocol.cia408.master import MasterSession
from ehpss_hil.protocol.cia408.objects import NmtState

CHANNEL = "master-session"
#: the master's config: other times than the emulator's power-on values, to see them written
MASTER = Cia408Config(heartbeat_time_ms=50, master_heartbeat_timeout_ms=250, setpoint_timeout_ms=20)


def test_start_up_writes_the_configuration_and_starts_the_nodes() -> None:
    with Cia408Rig({"interface": "virtual", "receive_own_messages": False, "channel": CHANNEL}) as r:
        bus = can.Bus(interface="virtual", channel=CHANNEL, receive_own_messages=False)
        try:
            codec = make_codec(
                "cia408", "", CanIds(), "test", None, MASTER, load_params().plant.spool_stroke_m
            )
            assert isinstance(codec, Cia408Codec)
            codec.scaling = replace(codec.scaling, step_m=1e-3)  # start-up reads the real one
            session = MasterSession(bus, MASTER)
            for (index, sub), value in {
                (0x6320, 1): 8000,
                (0x6321, 1): -8000,
                (0x6330, 0): 1,
                (0x6314, 1): 500,
            }.items():
                r.proc.valve.store.set(index, sub, value)  # a valve that came with limits and a ramp
            before = set(threading.enumerate())
            valve, encoder = session.start(codec)
            assert (valve.profile, encoder.profile) == (408, 406)
            v, e = r.proc.valve.store, r.proc.encoder.store
            assert v.get(0x1017) == e.get(0x1017) == 50
            assert v.get(0x1016, 1) == (1 << 16) | 250 and v.get(0x1400, 5) == 20
            assert (v.get(0x6042), v.get(0x6043)) == (1, 1)
            assert [v.get(0x6320, 1), v.get(0x6321, 1), v.get(0x6330), v.get(0x6314, 1)] == [
                16384,
                -16384,
                0,
                0,
            ]
            assert [v.get(0x1600, s) for s in (0, 1, 2)] == [2, 0x60400010, 0x63000110]
            assert [v.get(0x1A00, s) for s in (0, 1, 2)] == [2, 0x60410010, 0x63010110]
            assert [e.get(0x1A00, s) for s in (0, 1)] == [1, 0x60040020]
            assert v.get(0x1400, 1) == 0x220 and v.get(0x1800, 1) == 0x1A0 and e.get(0x1800, 1) == 0x1A1
            assert v.get(0x1400, 2) == v.get(0x1800, 2) == e.get(0x1800, 2) == 1
            assert r.proc.valve.nmt == r.proc.encoder.nmt == NmtState.OPERATIONAL
            assert codec.scaling.step_m == pytest.approx(100e-9, rel=1e-12)  # 0x6005.1 = 100 nm
            assert session.net.notifier is None
            assert set(threading.enumerate()) == before  # its notifier thread ended
            session.stop()
            assert wait_until(lambda: r.proc.valve.nmt == r.proc.encoder.nmt == NmtState.STOPPED)
        finally:
            bus.shutdown()


def test_a_node_that_never_answers_is_one_error_naming_it() -> None:
    bus = can.Bus(interface="virtual", channel="master-session-empty", receive_own_messages=False)
    try:
        codec = make_codec("cia408", "", CanIds(), "test", None, MASTER, load_params().plant.spool_stroke_m)
        assert isinstance(codec, Cia408Codec)
        with pytest.raises(NodeError) as exc:
            MasterSession(bus, MASTER, wait_s=1.5).start(codec)
        assert str(exc.value) == "valve node 32: no answer within 1.5 s" and exc.value.exit_code == 3
    finally:
        bus.shutdown()


def test_with_the_position_from_the_valve_its_tpdo2_is_mapped_and_no_encoder_started() -> None:
    c = replace(MASTER, position_source="valve")
    channel = "master-session-valve-position"
    with Cia408Rig({"interface": "virtual", "receive_own_messages": False, "channel": channel}) as r:
        bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        try:
            codec = make_codec("cia408", "", CanIds(), "test", None, c, load_params().plant.spool_stroke_m)
            assert isinstance(codec, Cia408Codec) and codec.can_id("SENSOR_POS") == 0x2A0
            session = MasterSession(bus, c)
            assert [i.profile for i in session.start(codec)] == [408]
            v = r.proc.valve.store
            assert [v.get(0x1801, s) for s in (1, 2)] == [0x2A0, 1]
            assert [v.get(0x1A01, s) for s in (0, 1)] == [1, 0x21000020]
            assert r.proc.valve.nmt == NmtState.OPERATIONAL
            assert r.proc.encoder.nmt == NmtState.PRE_OPERATIONAL  # not the master's
        finally:
            bus.shutdown()
