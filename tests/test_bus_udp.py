"""udp_multicast at the frame level: the own-ID socket filter (its BPF program run by a small
interpreter here, and by the kernel in a namespace) and the select()-free reader."""

from __future__ import annotations

import json
import random
import subprocess
import sys
import textwrap

import can
import pytest
from _proc import ROOT
from can.interfaces.udp_multicast.utils import pack_message

from ehpss_hil.bus import frame_reader
from ehpss_hil.bus_udp import own_id_program
from ehpss_hil.netns import netns_prefix, netns_unavailable_reason

NETNS_SKIP = netns_unavailable_reason()
netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"needs a namespace: {NETNS_SKIP}")
OWN = (0x120, 0x140, 0x141, 0x142, 0x701)


def _run_bpf(prog: list[tuple[int, int, int, int]], packet: bytes) -> int:
    """Classic BPF, the opcodes the filter uses: ld len, ld [k] (word/half/byte), jeq/jge #k,
    ret #k. An out-of-packet load returns 0 (drop), as in the kernel."""
    pc = a = 0
    while True:
        code, jt, jf, k = prog[pc]
        if code in (0x20, 0x28, 0x30):
            n = {0x20: 4, 0x28: 2, 0x30: 1}[code]
            if k + n > len(packet):
                return 0
            a = int.from_bytes(packet[k:k + n], "big")
            pc += 1
        elif code == 0x80:
            a = len(packet)
            pc += 1
        elif code in (0x15, 0x35):
            pc += 1 + (jt if (a == k if code == 0x15 else a >= k) else jf)
        elif code == 0x06:
            return k
        else:
            raise AssertionError(f"opcode 0x{code:02x}")


def _datagram(can_id: int, timestamp: float) -> bytes:
    msg = can.Message(arbitration_id=can_id, is_extended_id=can_id > 0x7FF, data=bytes(8),
                      timestamp=timestamp)
    return bytes(8) + pack_message(msg)  # the filter sees the UDP header first


def test_own_id_program_drops_exactly_the_own_ids() -> None:
    prog = own_id_program(OWN)
    assert prog is not None
    rng = random.Random(1)
    ids = [*OWN, 0x110, 0x111, 0x160, 0x161, 0x702, 0, 5, 0x7F, 0x80, 0xFF, 0x100, 0x7FF,
           0x1FFFF120, *(rng.randrange(0x800) for _ in range(300))]
    for can_id in ids:
        for ts in (0.0, 1.5, 1.7e9 + rng.random()):
            kept = _run_bpf(prog, _datagram(can_id, timestamp=ts))
            assert (kept == 0) == (can_id in OWN), hex(can_id)


def test_own_id_program_accepts_what_it_does_not_recognise() -> None:
    prog = own_id_program(OWN)
    assert prog is not None
    own = _datagram(0x120, timestamp=1.5)
    assert _run_bpf(prog, own) == 0
    for bad in (own[:20], own[:45], own[:8] + b"\x8a" + own[9:],
                own[:8] + own[8:19] + b"\xca" + own[20:], own[:30] + b"x" + own[31:], b"", bytes(100)):
        assert _run_bpf(prog, bad) != 0
    assert own_id_program([]) is None
    assert own_id_program([0x05, 0x85]) is not None  # fixint and uint8 encodings


def test_frame_reader_elsewhere_is_recv_zero() -> None:
    a = can.Bus(interface="virtual", channel="reader")
    b = can.Bus(interface="virtual", channel="reader")
    try:
        read = frame_reader(b)
        assert read() is None
        a.send(can.Message(arbitration_id=0x110, data=b"\x01", is_extended_id=False))
        got = read()
        assert got is not None and got.arbitration_id == 0x110 and read() is None
    finally:
        a.shutdown()
        b.shutdown()


_PROBE = textwrap.dedent("""
    import json, time, can
    from ehpss_hil.bus import open_bus, frame_reader, drop_own_frames
    from ehpss_hil.config import BusConfig
    a, b = open_bus(BusConfig()), open_bus(BusConfig())
    own = [0x120, 0x140, 0x701, 0x05, 0x85]
    attached = drop_own_frames(b, own)
    sent = [0x110, 0x120, 0x111, 0x140, 0x160, 0x701, 0x702, 0x05, 0x06, 0x85, 0x86, 0x1FFFF120]
    t0 = time.time()
    for i in sent:
        a.send(can.Message(arbitration_id=i, data=bytes([i & 0xFF] * 8), is_extended_id=i > 0x7FF))
    b.send(can.Message(arbitration_id=0x120, data=bytes(8), is_extended_id=False))  # own echo
    b.send(can.Message(arbitration_id=0x333, data=b"", is_extended_id=False))  # DLC 0, foreign
    time.sleep(0.2)
    read = frame_reader(b)
    got = []
    while (m := read()) is not None:
        got.append([m.arbitration_id, m.data.hex(), m.timestamp - t0])
    a.shutdown(); b.shutdown()
    print(json.dumps({"attached": attached, "got": got}))
""")


@netns
def test_kernel_drops_own_ids_and_reader_returns_the_rest() -> None:
    r = subprocess.run([*netns_prefix(), sys.executable, "-c", _PROBE], cwd=ROOT,
                       capture_output=True, text=True, timeout=60)
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["attached"] is True
    got = d["got"]
    assert [g[0] for g in got] == [0x110, 0x111, 0x160, 0x702, 0x06, 0x86, 0x1FFFF120, 0x333]
    assert all(g[1] == f"{g[0] & 0xFF:02x}" * 8 for g in got[:-1]) and got[-1][1] == ""
    assert all(0.0 <= g[2] < 0.2 for g in got)  # kernel receive timestamps, wall clock
