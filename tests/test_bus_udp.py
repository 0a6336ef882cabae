"""udp_multicast at the frame level: the own-datagram socket filter (its BPF program run by a
small interpreter here, and by the kernel in a namespace: a process's own frames are dropped,
another sender's on the same IDs are not), the select()-free reader and the template writer."""

from __future__ import annotations

import json
import random
import struct
import subprocess
import sys
import textwrap
from typing import Any

import can
import pytest
from _proc import ROOT
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from ehpss_hil.bus import frame_reader
from ehpss_hil.bus.netns import netns_prefix, netns_unavailable_reason
from ehpss_hil.bus.udp import own_source_program
from ehpss_hil.bus.udpwire import DatagramParser, template

NETNS_SKIP = netns_unavailable_reason()
netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"needs a namespace: {NETNS_SKIP}")


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
            a = int.from_bytes(packet[k : k + n], "big")
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


def _datagram(src_port: int, can_id: int) -> bytes:
    """A UDP header (source port, the group's port, length, checksum) and a frame: what a UDP
    socket filter sees."""
    body = pack_message(can.Message(arbitration_id=can_id, data=bytes(8), timestamp=1.5))
    return struct.pack(">HHHH", src_port, 43113, 8 + len(body), 0) + body


def test_own_source_program_drops_exactly_that_port() -> None:
    rng = random.Random(1)
    prog = own_source_program(40001)
    for port in (40001, 40000, 40002, 43113, 1, 65535, *(rng.randrange(1, 65536) for _ in range(200))):
        for can_id in (0x120, 0x110, 0x701):
            assert (_run_bpf(prog, _datagram(port, can_id)) == 0) == (port == 40001)
    assert _run_bpf(prog, b"") == 0  # no UDP header: never seen on a UDP socket


def test_writer_templates_give_pack_message_bytes() -> None:
    """Splicing a timestamp and data into a shape's template is python-can's ``pack_message``,
    byte for byte, for standard and extended IDs, every DLC, RTR and error frames."""
    rng = random.Random(3)
    shapes = 0
    for _ in range(400):
        n = rng.randrange(9)
        ext = rng.random() < 0.3
        msg = can.Message(
            arbitration_id=rng.randrange(1 << (29 if ext else 11)),
            is_extended_id=ext,
            data=rng.randbytes(n),
            dlc=n,
            is_remote_frame=rng.random() < 0.1,
            is_error_frame=rng.random() < 0.05,
            channel=rng.choice([None, "can0", 1]),
            timestamp=rng.choice([0.0, 1.5, 1.7e9 + rng.random(), -3.25]),
        )
        tpl = template(msg)
        assert tpl is not None, msg
        head, middle, tail = tpl
        spliced = head + struct.pack(">d", msg.timestamp) + middle + bytes(msg.data) + tail
        assert spliced == pack_message(msg), msg
        shapes += 1
    assert shapes == 400


_FIELDS = (
    "timestamp",
    "arbitration_id",
    "is_extended_id",
    "is_remote_frame",
    "is_error_frame",
    "channel",
    "dlc",
    "data",
    "is_fd",
    "bitrate_switch",
    "error_state_indicator",
    "is_rx",
)


def _unpacked(datagram: bytes, ts: float) -> tuple[Any, ...] | None:
    try:
        m = unpack_message(datagram, replace={"timestamp": ts}, check=True)
    except Exception:
        return None
    return tuple(getattr(m, f) for f in _FIELDS)


def test_parser_gives_what_unpack_message_gives() -> None:
    """Learnt shapes read off their templates give the same Message as ``unpack_message`` (every
    field, for the same datagrams and for datagrams with a byte changed anywhere); what
    ``unpack_message`` rejects is a CanOperationError; the shape table is bounded."""
    rng = random.Random(5)
    parser = DatagramParser()
    frames = [
        can.Message(arbitration_id=i, is_extended_id=i > 0x7FF, data=rng.randbytes(n), dlc=n)
        for i, n in ((0x110, 8), (0x111, 8), (0x05, 2), (0x1FFFF120, 8), (0x701, 1), (0x333, 0))
    ]
    frames.append(can.Message(arbitration_id=0x120, is_remote_frame=True, dlc=4))  # not learnt
    fast = 0
    for round_ in range(3):
        for f in frames:
            for _ in range(40):
                f.data = bytearray(rng.randbytes(len(f.data))) if not f.is_remote_frame else f.data
                f.timestamp = rng.random() * 2e9
                dg = bytearray(pack_message(f))
                if round_ == 2:  # corrupt one byte anywhere (key, type tag, ID, data, length)
                    dg[rng.randrange(len(dg))] = rng.randrange(256)
                ts = rng.random() * 2e9
                want = _unpacked(bytes(dg), ts)
                if want is None:
                    with pytest.raises(can.CanOperationError):
                        parser.parse(bytes(dg), ts)
                    continue
                before = parser.shapes
                got = parser.parse(bytes(dg), ts)
                fast += parser.shapes == before
                assert tuple(getattr(got, k) for k in _FIELDS) == want, (f, bytes(dg).hex())
    assert parser.shapes <= DatagramParser.MAX_SHAPES
    assert fast > 500  # most frames went the template way
    ready = DatagramParser()  # a shape learnt ahead (start-up) serves the first datagram
    ready.learn(can.Message(arbitration_id=0x110, dlc=8, data=bytes(8)))
    first = pack_message(can.Message(arbitration_id=0x110, dlc=8, data=b"abcdefgh", timestamp=2.0))
    got = ready.parse(first, 3.5)
    assert ready.shapes == 1 and tuple(getattr(got, k) for k in _FIELDS) == _unpacked(first, 3.5)
    full = DatagramParser()
    for i in range(200):
        full.parse(pack_message(can.Message(arbitration_id=i, data=b"x")), 1.0)
    assert full.shapes == DatagramParser.MAX_SHAPES


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
    from ehpss_hil.bus import open_bus, frame_reader, frame_writer, suppress_own_echoes
    from ehpss_hil.config import BusConfig
    a, b = open_bus(BusConfig()), open_bus(BusConfig())
    attached = suppress_own_echoes(b)
    sent = [0x110, 0x120, 0x111, 0x140, 0x160, 0x701, 0x702, 0x05, 0x06, 0x85, 0x86, 0x1FFFF120]
    t0 = time.time()
    write, write_b = frame_writer(a), frame_writer(b)
    for i in sent:  # every other one by python-can's send, the rest by the template writer
        send, own = (write, write_b) if i % 2 else (a.send, b.send)
        for s in (send, own):  # the same frame from a and from b itself
            s(can.Message(arbitration_id=i, data=bytes([i & 0xFF] * 8), is_extended_id=i > 0x7FF,
                          timestamp=time.time()))
    a.send(can.Message(arbitration_id=0x333, data=b"", is_extended_id=False))  # DLC 0
    time.sleep(0.2)
    read = frame_reader(b)
    got = []
    while (m := read()) is not None:
        got.append([m.arbitration_id, m.data.hex(), m.timestamp - t0])
    t_end = time.time() - t0
    a.shutdown(); b.shutdown()
    print(json.dumps({"attached": attached, "got": got, "t_end": t_end,
                      "writer": type(getattr(write, "__self__", None)).__name__}))
""")


@netns
def test_kernel_drops_own_datagrams_and_reader_returns_every_other_senders() -> None:
    """b's own frames never reach b; a's reach it on every ID, b's own IDs too."""
    r = subprocess.run(
        [*netns_prefix(), sys.executable, "-c", _PROBE], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["attached"] is True and d["writer"] == "UdpWriter"
    got = d["got"]
    assert [g[0] for g in got] == [
        0x110,
        0x120,
        0x111,
        0x140,
        0x160,
        0x701,
        0x702,
        0x05,
        0x06,
        0x85,
        0x86,
        0x1FFFF120,
        0x333,
    ]
    assert all(g[1] == f"{g[0] & 0xFF:02x}" * 8 for g in got[:-1]) and got[-1][1] == ""
    # kernel receive timestamps on the wall clock: between the first send and the last read
    assert all(0.0 <= g[2] <= d["t_end"] for g in got)


_STRAY = textwrap.dedent("""
    import json, socket, time, can, msgpack
    from ehpss_hil.bus import open_bus, frame_reader, datagram_rejects
    from ehpss_hil.config import BusConfig
    cfg = BusConfig()
    a, b, c = open_bus(cfg), open_bus(cfg), open_bus(cfg)
    raw = socket.socket(socket.AF_INET, socket.SOCK_DGRAM)
    garbage = [b"", b"hello", msgpack.packb(7), msgpack.packb({"bogus": 1}), bytes(60000),
               msgpack.packb({"timestamp": 1.0, "arbitration_id": 1, "data": b"x", "is_fd": True,
                              "dlc": 1})]
    for i, g in enumerate(garbage):
        raw.sendto(g, (cfg.channel, cfg.port))
        a.send(can.Message(arbitration_id=0x200 + i, data=b"", is_extended_id=False))
    time.sleep(0.2)
    read = frame_reader(b)
    fast = []
    while (m := read()) is not None:
        fast.append(m.arbitration_id)
    slow = []
    while (m := c.recv(0.05)) is not None:
        slow.append(m.arbitration_id)
    out = {"fast": fast, "slow": slow, "b": datagram_rejects(b).as_dict(),
           "c": datagram_rejects(c).as_dict()}
    a.shutdown(); b.shutdown(); c.shutdown()
    print(json.dumps(out))
""")


@netns
def test_stray_datagrams_are_counted_and_skipped_on_both_read_paths() -> None:
    r = subprocess.run(
        [*netns_prefix(), sys.executable, "-c", _STRAY], cwd=ROOT, capture_output=True, text=True, timeout=60
    )
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["fast"] == [0x200 + i for i in range(6)]
    reasons = {"empty": 1, "not msgpack": 1, "not a frame": 2, "oversize": 1, "CAN FD": 1}
    assert d["b"] == {"total": 6, "by_reason": dict(sorted(reasons.items()))}
    # python-can's recv drops DLC-0 frames ("if msg" is the length): only the rejects matter here
    assert d["c"] == d["b"]
