"""``canopen``'s own master against firmware-sim's CANopen nodes (a separate OS process).

Waits for the valve's boot-up, reads the identity of both nodes by SDO, starts them (NMT),
drives the valve to ACTIVE with a +20 % set-point in RPDO 1 and sends ``--cycles`` SYNCs (each
answered by both TPDOs), then stops them; prints ``ready`` once its bus is open and one JSON line
of what it saw. Must run where udp_multicast stays on this host (inside a private namespace).
"""

from __future__ import annotations

import argparse
import json
import sys
import time
from typing import Any

import canopen

from ehpss_hil.bus import open_bus, suppress_own_echoes
from ehpss_hil.config import BusConfig
from ehpss_hil.protocol.cia408.eds import ENCODER_EDS, VALVE_EDS

SETPOINT = 3277  #: +20 %


def _identity(node: Any) -> dict[str, int]:
    return {
        "device_type": node.sdo[0x1000].raw,
        "vendor_id": node.sdo[0x1018][1].raw,
        "product_code": node.sdo[0x1018][2].raw,
        "revision": node.sdo[0x1018][3].raw,
        "serial": node.sdo[0x1018][4].raw,
    }


def _state(node: Any, state: str) -> str:
    """Heartbeats until one shows ``state`` (one sent before the NMT command may come first)."""
    seen = node.nmt.wait_for_heartbeat(30)
    for _ in range(100):
        if seen == state:
            break
        seen = node.nmt.wait_for_heartbeat(30)
    return str(seen)


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--valve", type=int, default=32)
    p.add_argument("--encoder", type=int, default=33)
    p.add_argument("--cycles", type=int, default=100)
    p.add_argument("--startup", type=float, default=60.0)
    a = p.parse_args()
    bus = open_bus(BusConfig())
    suppress_own_echoes(bus)
    net = canopen.Network(bus)
    valve = net.add_node(a.valve, str(VALVE_EDS))
    encoder = net.add_node(a.encoder, str(ENCODER_EDS))
    net.connect()
    out: dict[str, Any] = {"states": []}
    try:
        print("ready", flush=True)
        valve.nmt.wait_for_bootup(a.startup)
        for n in (valve, encoder):
            n.sdo.RESPONSE_TIMEOUT = 5.0
        out["valve"] = _identity(valve)
        out["encoder"] = _identity(encoder)
        out["device_name"] = valve.sdo[0x1008].raw
        out["states"].append(valve.nmt.wait_for_heartbeat(30))
        for n in (valve, encoder):
            n.nmt.state = "OPERATIONAL"
            n.tpdo.read(from_od=True)
        out["states"].append(_state(valve, "OPERATIONAL"))
        valve.rpdo.read(from_od=True)
        rpdo, tv, te = valve.rpdo[1], valve.tpdo[1], encoder.tpdo[1]
        rows = []
        for _ in range(a.cycles):
            rpdo[0].raw, rpdo[1].raw = 0x0007, SETPOINT
            rpdo.transmit()
            tv.is_received = te.is_received = False
            net.sync.transmit()
            end = time.monotonic() + 30.0
            while not (tv.is_received and te.is_received) and time.monotonic() < end:
                time.sleep(0.001)
            rows.append((tv[0].raw, tv[1].raw, te[0].raw))
            time.sleep(0.005)
        out["tpdo"] = rows
        for n in (valve, encoder):
            n.nmt.state = "STOPPED"
        out["states"].append(_state(valve, "STOPPED"))
    finally:
        net.disconnect()
    print(json.dumps(out), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
