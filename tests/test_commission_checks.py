"""Commissioning checks (issue #28 item 4's smaller list): each mistake is one line with its exit
code, before anything moves — a position field narrower than the travel, a 24-bit float, a
load pressure on another multiplexer page, a node of another identity than the config's, a bit
rate other than the interface's; and a CiA 408 start-up that waits for its nodes says so in
one line of its own instead of canopen's ``Transfer aborted`` error."""

from __future__ import annotations

import logging
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import can
import pytest
from _cia408 import Cia408Rig
from _proc import EHPSS_HIL, FIRMWARE_SIM, Proc

from ehpss_hil.bus.bitrate import check_bitrate, parse_ip_link
from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason
from ehpss_hil.config import BusConfig, CanIds, Cia408Config, load_controller_config
from ehpss_hil.errors import ConfigError, NodeError
from ehpss_hil.physics.load import load_params
from ehpss_hil.profile_config import NodeIdentityConfig
from ehpss_hil.protocol import make_codec
from ehpss_hil.protocol.cia408.codec import Cia408Codec
from ehpss_hil.protocol.cia408.master import MasterSession

ROOT = Path(__file__).resolve().parent.parent
NETNS_SKIP = netns_unavailable_reason()
VENDOR_DBC = ROOT / "dbc" / "vendor-example.dbc"
VENDOR_CFG = ROOT / "configs" / "controller-vendor.yaml"


def _vendor_config(tmp: Path, dbc_text: str, extra: str = "") -> Path:
    """configs/controller-vendor.yaml with its own copy of the vendor DBC (``dbc_text``)."""
    (tmp / "vendor.dbc").write_text(dbc_text)
    text = VENDOR_CFG.read_text()
    text = text.replace("../dbc/vendor-example.dbc", "vendor.dbc")
    text = text.replace("params: params.yaml", f"params: {ROOT / 'configs' / 'params.yaml'}")
    text = text.replace("dbc: ../dbc/ehpss.dbc", f"dbc: {ROOT / 'dbc' / 'ehpss.dbc'}")
    p = tmp / "controller.yaml"
    p.write_text(text + extra)
    return p


def _check_config(path: Path) -> tuple[int, list[str]]:
    out = subprocess.run(
        [sys.executable, "-m", "ehpss_hil.cli", "check-config", str(path)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    assert out.stdout == "" or out.returncode == 0, out
    return out.returncode, out.stderr.splitlines()


def _vendor(old: str, new: str) -> str:
    text = VENDOR_DBC.read_text()
    assert old in text
    return text.replace(old, new)


BAD_VENDOR: list[tuple[str, str, str, str]] = [
    (
        "position range narrower than the travel",
        _vendor("PistonPos : 23|22@0- (0.0005,0) [-500|500]", "PistonPos : 23|22@0- (0.0005,0) [-0.5|0.5]"),
        "dbc_map.signals.position",
        "AMP_FEEDBACK.PistonPos holds [-0.0005, 0.0005] m; the piston is sent to ±0.001 m (reference), "
        "so the field must hold ±0.0012 m (×1.2)",
    ),
    (
        "24-bit float",
        _vendor(
            'PistonPos : 23|22@0- (0.0005,0) [-500|500] "mm"', 'PistonPos : 16|24@1- (1,0) [-500|500] "mm"'
        )
        + "SIG_VALTYPE_ 210 PistonPos : 1;\n",
        "dbc_map.signals.position",
        "PistonPos is a 24-bit float; a DBC float is IEEE 754 single (32 bits) or double (64 bits)",
    ),
    (
        "load pressure on another page",
        _vendor("SG_ LoadPress m0 :", "SG_ LoadPress m1 :")
        .replace("SG_ OilTemp m1 : 16|8@1+", "SG_ OilTemp m1 : 56|8@1+")
        .replace("SG_ SupplyPress m1 : 24|16@1+", "SG_ SupplyPress m1 : 40|16@1+"),
        "dbc_map.signals.load_pressure",
        "LoadPress is on multiplexer page Page=1, CoilCurrent (coil_current) on Page=0: SENSOR_AUX's "
        "signals must share one page",
    ),
    (
        "an echo coarser than the sweep's limit",
        _vendor("CoilCurrent m0 : 39|20@0- (0.002,0)", "CoilCurrent m0 : 39|20@0- (0.004,0)"),
        "dbc_map.signals.coil_current",
        "CoilCurrent has an LSB of 4e-06 (factor 0.004 mA), coarser than the 3e-06 SI units",
    ),
]


@pytest.mark.parametrize(("what", "dbc", "key", "reason"), BAD_VENDOR, ids=[b[0] for b in BAD_VENDOR])
def test_a_vendor_dbc_mistake_is_one_check_config_line_exit_2(
    tmp_path: Path, what: str, dbc: str, key: str, reason: str
) -> None:
    rc, lines = _check_config(_vendor_config(tmp_path, dbc))
    assert rc == 2 and len(lines) == 1, lines
    assert f"controller.yaml: {key}: " in lines[0] and reason in lines[0], lines[0]
    assert "Traceback" not in lines[0]


def test_sim_refuses_a_scenario_that_leaves_the_position_field(tmp_path: Path) -> None:
    """The shipped vendor map holds ±0.5 m; a scenario sending the piston to 0.45 m does not fit
    ×1.2: one line naming the field, exit 2, before any run."""
    sc = tmp_path / "far.yaml"
    sc.write_text("name: far\nduration_s: 0.1\nreference: {kind: step, amplitude_m: 0.45}\nevents: []\n")
    out = subprocess.run(
        [sys.executable, "-m", "ehpss_hil.cli", "sim", str(sc), "-C", "nrc", "--protocol", str(VENDOR_CFG)],
        capture_output=True,
        text=True,
        timeout=120,
        check=False,
    )
    lines = out.stderr.splitlines()
    assert out.returncode == 2 and len(lines) == 1, out
    assert "dbc_map.signals.position: AMP_FEEDBACK.PistonPos holds [-0.5, 0.5] m" in lines[0]
    assert f"the reference of {sc}" in lines[0]


def test_check_config_takes_the_identity_keys(tmp_path: Path) -> None:
    text = (ROOT / "configs" / "controller-cia408.yaml").read_text()
    p = tmp_path / "controller-cia408.yaml"
    p.write_text(
        text.replace("params: params.yaml", f"params: {ROOT / 'configs' / 'params.yaml'}")
        .replace("dbc: ../dbc/ehpss.dbc", f"dbc: {ROOT / 'dbc' / 'ehpss.dbc'}")
        .replace("cia408:\n", "cia408:\n  valve_identity: {vendor_id: 0xEE5, product_code: 0x408}\n", 1)
    )
    cfg = load_controller_config(p)
    assert cfg.nodes.valve_identity == NodeIdentityConfig(0xEE5, 0x408, None)
    rc, lines = _check_config(p)
    assert rc == 0, lines


def _master_codec(c: Cia408Config) -> Cia408Codec:
    codec = make_codec("cia408", "", CanIds(), "test", None, c, load_params().plant.spool_stroke_m)
    assert isinstance(codec, Cia408Codec)
    return codec


def test_a_node_of_another_identity_is_refused_in_one_line() -> None:
    """The emulated valve impersonates product 0x409 (the config keys the emulator reads); a
    master whose config expects 0x408 stops at the identity check (exit 3)."""
    channel = "commission-identity"
    emu_cfg = replace(Cia408Config(), valve_identity=NodeIdentityConfig(product_code=0x409))
    master = replace(Cia408Config(), valve_identity=NodeIdentityConfig(vendor_id=0xEE5, product_code=0x408))
    with Cia408Rig({"interface": "virtual", "receive_own_messages": False, "channel": channel}, emu_cfg):
        bus = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        try:
            with pytest.raises(NodeError) as exc:
                MasterSession(bus, master).start(_master_codec(master))
        finally:
            bus.shutdown()
    assert str(exc.value) == (
        "valve node 32: 0x1018.2 product_code is 0x00000409, the config "
        "(cia408.valve_identity.product_code) expects 0x00000408"
    )
    assert exc.value.exit_code == 3


def test_waiting_for_a_node_logs_one_line_and_no_canopen_abort(caplog: pytest.LogCaptureFixture) -> None:
    """Every SDO read of a node that has not booted times out; canopen logs each as ``Transfer
    aborted by client with code 0x05040000``. The start-up logs one line that it waits instead,
    and refuses after its wait with one NodeError line (exit 3)."""
    bus = can.Bus(interface="virtual", channel="commission-no-node", receive_own_messages=False)
    c = Cia408Config()
    try:
        with caplog.at_level(logging.INFO), pytest.raises(NodeError) as exc:
            MasterSession(bus, c, wait_s=2.5).start(_master_codec(c))
    finally:
        bus.shutdown()
    assert str(exc.value) == "valve node 32: no answer within 2.5 s" and exc.value.exit_code == 3
    texts = [r.getMessage() for r in caplog.records]
    assert not [t for t in texts if "Transfer aborted" in t], texts
    assert texts.count("valve node 32: no SDO answer yet; waiting up to 2.5 s") == 1, texts
    # outside the start-up canopen's own record is untouched
    caplog.clear()
    with caplog.at_level(logging.ERROR):
        logging.getLogger("canopen.sdo.client").error(
            "Transfer aborted by client with code 0x%08X", 0x05040000
        )
    assert len(caplog.records) == 1


#: ``ip -details -json link show dev can0`` of a CAN controller at 500 kbit/s (iproute2 6.1)
IP_CAN0 = (
    '[{"ifindex":4,"ifname":"can0","flags":["NOARP","UP","LOWER_UP","ECHO"],"mtu":16,'
    '"qdisc":"pfifo_fast","operstate":"UP","linkmode":"DEFAULT","group":"default","txqlen":1000,'
    '"link_type":"can","promiscuity":0,"min_mtu":0,"max_mtu":0,"linkinfo":{"info_kind":"can",'
    '"info_data":{"ctrlmode":[],"state":"ERROR-ACTIVE","berr_counter":{"tx":0,"rx":0},'
    '"restart_ms":100,"bittiming":{"bitrate":500000,"sample_point":"0.875","tq":125,"prop_seg":6,'
    '"phase_seg1":7,"phase_seg2":2,"sjw":1,"brp":1},"bittiming_const":{"name":"mcp251x","tseg1":'
    '{"min":3,"max":16},"tseg2":{"min":2,"max":8},"sjw":{"min":1,"max":4},"brp":{"min":1,"max":64},'
    '"brp_inc":1},"clock":8000000}},"num_tx_queues":1,"num_rx_queues":1}]'
)
#: the same of a vcan interface: no bit timing
IP_VCAN0 = '[{"ifindex":5,"ifname":"vcan0","link_type":"can","linkinfo":{"info_kind":"vcan"}}]'


def test_the_bit_rate_is_checked_where_the_interface_has_one() -> None:
    assert parse_ip_link(IP_CAN0) == 500000
    assert parse_ip_link(IP_VCAN0) is None and parse_ip_link("not json") is None
    cfg = BusConfig(interface="socketcan", channel="can0", bitrate=1_000_000)
    with pytest.raises(ConfigError) as exc:
        check_bitrate(cfg, "controller.yaml", parse_ip_link(IP_CAN0))
    assert str(exc.value) == (
        "controller.yaml: bus.bitrate: 1000000 bit/s, but can0 runs at 500000 bit/s (ip -details link "
        "show can0); set the interface or the config to the valve's bit rate"
    )
    assert exc.value.exit_code == 2
    assert check_bitrate(replace(cfg, bitrate=500000), "c", 500000) == (
        "bit rate: socketcan:can0 runs at 500000 bit/s as configured"
    )
    # a real interface without bit timing (the loopback here) and the embedded bus: not checked
    lo = BusConfig(interface="socketcan", channel="lo")
    assert check_bitrate(lo, "c") == "bit rate: socketcan:lo exposes none; bus.bitrate 1000000 not checked"
    assert "exposes none" in check_bitrate(BusConfig(), "c")


def _cia408_configs(tmp: Path, valve_product: int, expect_product: int) -> tuple[Path, Path]:
    """The shipped CiA 408 pair, the emulated valve impersonating ``valve_product`` and the
    master expecting ``expect_product``."""
    fix = {
        "params: params.yaml": f"params: {ROOT / 'configs' / 'params.yaml'}",
        "dbc: ../dbc/ehpss.dbc": f"dbc: {ROOT / 'dbc' / 'ehpss.dbc'}",
        "../scenarios/": f"{ROOT / 'scenarios'}/",
    }
    out = []
    for name, product in (
        ("emulator-cia408.yaml", valve_product),
        ("controller-cia408.yaml", expect_product),
    ):
        text = (ROOT / "configs" / name).read_text()
        for old, new in fix.items():
            text = text.replace(old, new)
        text = text.replace("cia408:\n", f"cia408:\n  valve_identity: {{product_code: {product:#x}}}\n", 1)
        p = tmp / name
        p.write_text(text)
        out.append(p)
    return out[0], out[1]


@pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
def test_the_controller_waits_for_the_valve_then_refuses_its_identity(tmp_path: Path) -> None:
    """The controller starts first (the valve boots later): one 'waiting' line, no canopen abort
    line; the valve that then answers is product 0x409 where the config expects 0x408: one
    line naming it, exit 3."""
    emu_cfg, ctl_cfg = _cia408_configs(tmp_path, 0x409, 0x408)
    with PrivateNetns() as ns:
        ctl = Proc(ns.prefix() + EHPSS_HIL + ["controller", "-c", str(ctl_cfg), "--duration", "5"])
        emu = None
        try:
            assert ctl.wait_for("no SDO answer yet", 120.0), ctl.text
            emu = Proc(ns.prefix() + FIRMWARE_SIM + ["-c", str(emu_cfg), "--duration", "300"])
            assert ctl.wait(180.0) == 3, ctl.text
        finally:
            ctl.kill()
            if emu is not None:
                emu.kill()
    err = "".join(ctl.err)
    assert "Transfer aborted" not in err and "Traceback" not in err, err
    assert err.count("valve node 32: no SDO answer yet; waiting up to 120 s") == 1, err
    last = [line for line in ctl.err if "error:" in line]
    assert last == [
        "ehpss-hil controller: error: valve node 32: 0x1018.2 product_code is 0x00000409, the config "
        "(cia408.valve_identity.product_code) expects 0x00000408\n"
    ], err
