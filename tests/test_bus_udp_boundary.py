"""The edge to python-can's ``udp_multicast`` internals: :mod:`ehpss_hil.bus.udp` (which reads
private attributes of python-can's bus) is imported only when a udp_multicast bus is opened,
python-can is bounded below its next major version, and its wire format is pinned byte for byte
so that a python-can that packs frames otherwise fails here, loudly, not in the field."""

from __future__ import annotations

import json
import subprocess
import sys
import textwrap
import tomllib

import can
import pytest
from _proc import ROOT
from can.interfaces.udp_multicast.utils import pack_message, unpack_message

from ehpss_hil.bus.netns import netns_prefix, netns_unavailable_reason

NETNS_SKIP = netns_unavailable_reason()
netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"needs a namespace: {NETNS_SKIP}")

_UDP = "ehpss_hil.bus.udp"


def _run(code: str, prefix: list[str] | None = None) -> dict[str, object]:
    r = subprocess.run(
        [*(prefix or []), sys.executable, "-c", textwrap.dedent(code)],
        cwd=ROOT,
        capture_output=True,
        text=True,
        timeout=120,
    )
    assert r.returncode == 0, r.stderr
    out: dict[str, object] = json.loads(r.stdout.splitlines()[-1])
    return out


def test_bus_package_and_daemon_do_not_load_the_udp_module() -> None:
    """Importing the bus factory and the daemon, and using a virtual bus through every helper,
    leaves :mod:`ehpss_hil.bus.udp` (and python-can's udp_multicast) unloaded."""
    d = _run("""
        import json, sys, can
        import ehpss_hil.bus, ehpss_hil.daemon
        from ehpss_hil.bus import open_bus, frame_reader, frame_writer, suppress_own_echoes, datagram_rejects
        from ehpss_hil.config import BusConfig
        names = ("ehpss_hil.bus.udp", "can.interfaces.udp")
        udp = lambda: sorted(m for m in sys.modules if m.startswith(names))
        after_import = udp()
        a = open_bus(BusConfig(interface="virtual", channel="lazy"))
        b = open_bus(BusConfig(interface="virtual", channel="lazy"))
        frame_writer(a)(can.Message(arbitration_id=0x110, data=b"\\x01", is_extended_id=False))
        got = frame_reader(b)()
        own = suppress_own_echoes(b)
        rejects = datagram_rejects(b)
        a.shutdown(); b.shutdown()
        print(json.dumps({"import": after_import, "use": udp(),
                          "got": got.arbitration_id, "own": own, "rejects": rejects is None}))
    """)
    assert d == {"import": [], "use": [], "got": 0x110, "own": True, "rejects": True}


@netns
def test_opening_a_udp_multicast_bus_loads_the_udp_module_and_its_fast_paths() -> None:
    """Opening udp_multicast imports :mod:`ehpss_hil.bus.udp`, and the private python-can
    attributes it reads are still there: the select()-free reader and the template writer are
    chosen and the own-source kernel filter attaches (a python-can that renamed them would fall
    back silently; this test makes that loud)."""
    d = _run(
        f"""
        import json, sys
        import ehpss_hil.bus
        from ehpss_hil.bus import open_bus, frame_reader, frame_writer, suppress_own_echoes
        from ehpss_hil.config import BusConfig
        before = "{_UDP}" in sys.modules
        bus = open_bus(BusConfig())
        loaded = "{_UDP}" in sys.modules
        reader = type(frame_reader(bus).__self__).__name__
        writer = type(frame_writer(bus).__self__).__name__
        own = suppress_own_echoes(bus)
        bus.shutdown()
        print(json.dumps({{"before": before, "loaded": loaded, "reader": reader, "writer": writer,
                          "own": own}}))
        """,
        netns_prefix(),
    )
    assert d == {"before": False, "loaded": True, "reader": "UdpReader", "writer": "UdpWriter", "own": True}


def test_python_can_is_bounded_below_its_next_major_version() -> None:
    deps = tomllib.loads((ROOT / "pyproject.toml").read_text())["project"]["dependencies"]
    (spec,) = [d for d in deps if d.replace(" ", "").startswith("python-can")]
    assert "<5" in spec.replace(" ", ""), spec
    assert int(can.__version__.split(".")[0]) == 4


#: python-can 4's udp_multicast datagram of two frames: a msgpack map of 11 keys in this order
_GOLDEN = [
    (
        can.Message(
            timestamp=1700000000.25, arbitration_id=0x110, is_extended_id=False, data=bytes(range(1, 9))
        ),
        "8ba974696d657374616d70cb41d954fc40100000ae6172626974726174696f6e5f6964cd0110ae69735f657874"
        "656e6465645f6964c2af69735f72656d6f74655f6672616d65c2ae69735f6572726f725f6672616d65c2a76368"
        "616e6e656cc0a3646c6308a464617461c4080102030405060708a569735f6664c2ae626974726174655f737769"
        "746368c2b56572726f725f73746174655f696e64696361746f72c2",
    ),
    (
        can.Message(timestamp=1.5, arbitration_id=0x1FFFF120, is_extended_id=True, data=b"\xaa\x55"),
        "8ba974696d657374616d70cb3ff8000000000000ae6172626974726174696f6e5f6964ce1ffff120ae69735f65"
        "7874656e6465645f6964c3af69735f72656d6f74655f6672616d65c2ae69735f6572726f725f6672616d65c2a7"
        "6368616e6e656cc0a3646c6302a464617461c402aa55a569735f6664c2ae626974726174655f73776974636"
        "8c2b56572726f725f73746174655f696e64696361746f72c2",
    ),
]


@pytest.mark.parametrize("msg, golden", _GOLDEN, ids=["standard", "extended"])
def test_udp_multicast_wire_format_is_pinned(msg: can.Message, golden: str) -> None:
    """The bytes python-can packs and unpacks are these (the writer's templates, the parser's
    shapes and the kernel filter's offsets depend on them)."""
    assert pack_message(msg).hex() == golden
    back = unpack_message(bytes.fromhex(golden), check=True)
    assert (back.timestamp, back.arbitration_id, back.is_extended_id, bytes(back.data)) == (
        msg.timestamp,
        msg.arbitration_id,
        msg.is_extended_id,
        bytes(msg.data),
    )
