"""The emulated nodes' identification, error history and encoder objects (issue #28 item 5),
each read by ``canopen``'s own master (not our code) over a virtual bus: versions 0x1009/0x100A,
the CiA 408 valve identification 0x6050–0x6057, the error history 0x1003 filled by the valve's
EMCYs and cleared by writing 0, the control deviation monitoring 0x6350–0x6355 with its window's
effect on the status word, and the CiA 406 encoder's 0x6000/0x6002/0x6003/0x6030/
0x6500–0x650B with a preset that moves the position value. Nothing is timed."""

from __future__ import annotations

import struct

import canopen
import pytest
from _cia408 import Cia408Rig, emcy_codes, heartbeat_state, wait_until

from ehpss_hil.config import Cia408Config
from ehpss_hil.protocol.cia408 import cobid

VIRTUAL = {"interface": "virtual", "receive_own_messages": False}


def _rig(name: str, **kw: object) -> Cia408Rig:
    return Cia408Rig({**VIRTUAL, "channel": f"cia408-obj-{name}"}, **kw)  # type: ignore[arg-type]


def test_versions_and_the_valve_identification_read_as_the_eds_says() -> None:
    with _rig("ident") as r:
        for node in (r.valve, r.encoder):
            assert node.sdo[0x1009].raw == "emulated" and node.sdo[0x100A].raw == "ehpss-hil 1.0"
        ident = {i: r.valve.sdo[i].raw for i in range(0x6050, 0x6058)}
        assert ident[0x6051] == "EHPSS-EMU-408" and ident[0x6057] == "ehpss-hil"
        assert ident[0x6056] == 0 and all(isinstance(ident[i], str) and ident[i] for i in (0x6050, 0x6053))
        with pytest.raises(canopen.SdoAbortedError):
            r.valve.sdo[0x6051].raw = "X"  # const


def test_the_error_history_holds_the_emcy_codes_newest_first_and_clears_on_zero() -> None:
    v = 32
    with _rig("history", cfg=Cia408Config(setpoint_timeout_ms=20)) as r:
        assert r.valve.sdo[0x1003][0].raw == 0
        r.valve.nmt.state = "OPERATIONAL"
        assert heartbeat_state(r.valve, "OPERATIONAL") == "OPERATIONAL"
        r.net.send_message(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 0))  # ACTIVE, then silence
        assert wait_until(lambda: 0x8250 in emcy_codes(r.valve))  # the set-point RPDO timed out
        r.net.send_message(cobid.RPDO1 + v, struct.pack("<H", 0x0001))  # 2 of 4 bytes
        assert wait_until(lambda: 0x8210 in emcy_codes(r.valve))
        assert r.valve.sdo[0x1003][0].raw == 2
        assert [r.valve.sdo[0x1003][s].raw for s in (1, 2, 3)] == [0x8210, 0x8250, 0]
        with pytest.raises(canopen.SdoAbortedError) as exc:
            r.valve.sdo[0x1003][0].raw = 1
        assert exc.value.code == 0x06090030
        r.valve.sdo[0x1003][0].raw = 0
        assert r.valve.sdo[0x1003][0].raw == 0 and r.valve.sdo[0x1003][1].raw == 0


def test_the_encoder_objects_and_its_preset() -> None:
    with _rig("encoder") as r:
        e = r.encoder
        assert e.sdo[0x6002].raw == 1_000_000 and e.sdo[0x6501].raw == 100 and e.sdo[0x6502].raw == 0
        assert [e.sdo[i].raw for i in (0x6503, 0x6504, 0x6505, 0x6506)] == [0, 1, 0, 0]
        assert e.sdo[0x6507].raw == 0x01000402 and e.sdo[0x650B].raw == 1
        assert [e.sdo[0x650A][s].raw for s in (1, 2, 3)] == [0, -500_000, 500_000]
        e.sdo[0x6000].raw = 0x0004
        assert e.sdo[0x6500].raw == 0x0004  # the operating status shows the parameters set
        assert e.sdo[0x6030][1].raw == 0  # at rest (no current, no noise)
        before = e.sdo[0x6004].raw
        e.sdo[0x6003].raw = 12345
        assert e.sdo[0x6004].raw == 12345 and e.sdo[0x6509].raw == 12345 - before


def test_the_setpoint_path_objects_by_sdo() -> None:
    """The set-point path read and written by canopen's master: defaults (±100 %, no ramp, hold
    0), an upper limit that clips +100 % (demand 0x6311.1 at the limit, status word bit 10)."""
    v = 32
    with _rig("setpoint") as r:
        sdo = r.valve.sdo
        assert [sdo[0x6320][1].raw, sdo[0x6321][1].raw, sdo[0x6330].raw, sdo[0x6331][1].raw] == [
            16384,
            -16384,
            0,
            0,
        ]
        assert sdo[0x6314][1].raw == 0 and sdo[0x6311][1].raw == 0
        with pytest.raises(canopen.SdoAbortedError):
            sdo[0x6330].raw = 2  # only 0 (none) and 1 (linear)
        sdo[0x6320][1].raw = 4096
        r.valve.nmt.state = "OPERATIONAL"
        assert heartbeat_state(r.valve, "OPERATIONAL") == "OPERATIONAL"
        r.net.send_message(cobid.RPDO1 + v, struct.pack("<Hh", 0x0007, 16384))
        assert wait_until(lambda: sdo[0x6041].raw == 0x040F)
        assert sdo[0x6311][1].raw == 4096 and sdo[0x6300][1].raw == 16384


def test_the_control_mode_and_deviation_monitoring_objects_by_sdo() -> None:
    """0x6043 takes 1 (open loop) and 2 (the valve's own spool loop), nothing else; the
    monitoring objects read their defaults and take a threshold; the deviation reads 0 at rest."""
    with _rig("deviation") as r:
        sdo = r.valve.sdo
        sdo[0x6043].raw = 2
        assert sdo[0x6043].raw == 2
        with pytest.raises(canopen.SdoAbortedError):
            sdo[0x6043].raw = 3
        assert [sdo[0x6350].raw, sdo[0x6351].raw, sdo[0x6352].raw, sdo[0x6353].raw] == [0, 0, 0, 1638]
        assert [sdo[0x6354].raw, sdo[0x6355].raw] == [1638, -1638]
        sdo[0x6353].raw = 800
        sdo[0x6351].raw = 1
        assert sdo[0x6353].raw == 800 and sdo[0x6351].raw == 1 and sdo[0x6041].raw & 0x0800 == 0
        sdo[0x6354].raw, sdo[0x6355].raw = 300, -16384
        sdo[0x6351].raw = 2
        assert [sdo[0x6351].raw, sdo[0x6354].raw, sdo[0x6355].raw] == [2, 300, -16384]
        for index, bad in ((0x6351, 3), (0x6354, 16385), (0x6355, -16385)):
            with pytest.raises(canopen.SdoAbortedError):
                sdo[index].raw = bad


def test_the_monitoring_window_sets_and_clears_status_bit_11() -> None:
    """Type 2 judges the deviation (0 at rest) against the window [0x6355, 0x6354]: a window
    that excludes 0 on either side sets bit 11 after the delay, one around 0 clears it, and the
    symmetric type 1 ignores the window."""
    with _rig("window") as r:
        sdo = r.valve.sdo
        assert sdo[0x6350].raw == 0
        sdo[0x6352].raw = 5  # ms
        sdo[0x6355].raw, sdo[0x6354].raw = 100, 200  # deviation 0 is below the window
        sdo[0x6351].raw = 2
        assert wait_until(lambda: sdo[0x6041].raw & 0x0800)
        sdo[0x6355].raw = -100  # [-100, 200] holds 0
        assert wait_until(lambda: not sdo[0x6041].raw & 0x0800)
        sdo[0x6355].raw, sdo[0x6354].raw = -200, -100  # 0 above the window
        assert wait_until(lambda: sdo[0x6041].raw & 0x0800)
        sdo[0x6351].raw = 1  # symmetric ±0x6353 (1638) holds 0
        assert wait_until(lambda: not sdo[0x6041].raw & 0x0800)
        sdo[0x6351].raw = 2
        assert wait_until(lambda: sdo[0x6041].raw & 0x0800)
        sdo[0x6351].raw = 0  # off
        assert wait_until(lambda: not sdo[0x6041].raw & 0x0800)
