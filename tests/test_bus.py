"""The bus factory: virtual, socketcan (missing → BusUnavailableError; kernel filters in the VM
suite), udp_multicast (hop limit 0, raised receive buffer, own frames seen — in a namespace)."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap

import can
import pytest
from _proc import EMU_CFG_PATH, FIRMWARE_SIM, ROOT

from ehpss_hil.bus import af_can_available, open_bus
from ehpss_hil.bus.netns import netns_prefix, netns_unavailable_reason
from ehpss_hil.config import BusConfig
from ehpss_hil.errors import BusUnavailableError, ConfigError

NETNS_SKIP = netns_unavailable_reason()
netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"needs a namespace: {NETNS_SKIP}")


def test_virtual_bus_peers_see_each_other_not_themselves() -> None:
    a = open_bus(BusConfig(interface="virtual", channel="test-bus"))
    b = open_bus(BusConfig(interface="virtual", channel="test-bus"))
    try:
        a.send(can.Message(arbitration_id=0x120, data=b"\x01" * 8, is_extended_id=False))
        got = b.recv(1.0)
        assert got is not None and got.arbitration_id == 0x120
        assert a.recv(0.0) is None
    finally:
        a.shutdown()
        b.shutdown()


@pytest.mark.skipif(af_can_available(), reason="this kernel has SocketCAN")
def test_socketcan_without_af_can_is_bus_unavailable() -> None:
    with pytest.raises(BusUnavailableError, match="SocketCAN"):
        open_bus(BusConfig(interface="socketcan", channel="vcan0"))


def test_udp_multicast_must_stay_on_host() -> None:
    with pytest.raises(ConfigError, match=r"239\.0\.0\.0/8"):
        BusConfig(interface="udp_multicast", channel="224.1.2.3")


@pytest.mark.socketcan
@pytest.mark.skipif(not af_can_available(), reason="no SocketCAN (socket(AF_CAN) failed)")
def test_socketcan_kernel_filters() -> None:
    cfg = BusConfig(interface="socketcan", channel="vcan0")
    rx = open_bus(cfg, can_filters=[{"can_id": 0x120, "can_mask": 0x7FF}])
    tx = open_bus(cfg)
    try:
        for fid in (0x110, 0x120):
            tx.send(can.Message(arbitration_id=fid, data=bytes(8), is_extended_id=False))
        got = rx.recv(2.0)
        assert got is not None and got.arbitration_id == 0x120
        assert rx.recv(0.2) is None
    finally:
        rx.shutdown()
        tx.shutdown()


_UDP_PROBE = textwrap.dedent("""
    import json, socket, can
    from ehpss_hil.bus import open_bus
    from ehpss_hil.config import BusConfig
    bus = open_bus(BusConfig(receive_buffer_bytes=2 * 2**20))
    sock = bus._multicast._socket
    ttl = sock.getsockopt(socket.IPPROTO_IP, socket.IP_MULTICAST_TTL)
    rcvbuf = sock.getsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF)
    bus.send(can.Message(arbitration_id=0x120, data=bytes(8), is_extended_id=False))
    echo = bus.recv(2.0)
    bus.shutdown()
    print(json.dumps({"ttl": ttl, "rcvbuf": rcvbuf, "echo": echo.arbitration_id if echo else None}))
""")


@netns
def test_udp_multicast_in_namespace_ttl0_rcvbuf_and_own_echo() -> None:
    r = subprocess.run(
        [*netns_prefix(), sys.executable, "-c", _UDP_PROBE],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 0, r.stderr
    d = json.loads(r.stdout)
    assert d["ttl"] == 0
    assert d["rcvbuf"] >= 2 * 2**20
    assert d["echo"] == 0x120  # it sees its own frame: the loops filter by ID/direction


@netns
def test_udp_multicast_without_route_exits_3() -> None:
    """A bare namespace (loopback down, no multicast route): the emulator cannot open its bus."""
    r = subprocess.run(
        ["unshare", "--net", "--", *FIRMWARE_SIM, "-c", EMU_CFG_PATH],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert r.returncode == 3, r.stderr
    assert "udp_multicast" in r.stderr


@pytest.mark.socketcan
@pytest.mark.skipif(not af_can_available(), reason="no SocketCAN (socket(AF_CAN) failed)")
def test_socketcan_missing_channel_is_bus_unavailable() -> None:
    with pytest.raises(BusUnavailableError, match="vcan9"):
        open_bus(BusConfig(interface="socketcan", channel="vcan9"))
