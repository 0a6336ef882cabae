"""A small test client for the emulator on the embedded bus (run as a separate OS process).

Answers every SENSOR_POS/SENSOR_AUX pair with one VALVE_CMD (a deterministic P law on the
received position), sends one VALVE_CMD with a corrupted CRC after the 10th answer, prints
``ready`` once its bus is open and a JSON line of counters at the end. Ends after ``--pairs``
answers or when the bus has been quiet for ``--idle`` seconds after its first frame (before it,
the peer's start-up may take up to ``--startup`` seconds on a loaded host).

Must run where udp_multicast stays on this host (hop limit 0, inside a private namespace).
"""

from __future__ import annotations

import argparse
import json
import sys

import can
import numpy as np

from ehpss_hil.bus import open_bus
from ehpss_hil.codec import FrameCodec
from ehpss_hil.config import BusConfig


def main() -> int:
    p = argparse.ArgumentParser()
    p.add_argument("--pairs", type=int, default=10**9)
    p.add_argument("--idle", type=float, default=3.0)
    p.add_argument("--startup", type=float, default=30.0)
    p.add_argument("--no-bad", action="store_true")
    a = p.parse_args()
    codec = FrameCodec()
    bus = open_bus(BusConfig())
    own = codec.can_id("VALVE_CMD")
    answered = bad = 0
    pos = None
    print("ready", flush=True)
    try:
        wait_s = a.startup
        while answered < a.pairs and (msg := bus.recv(wait_s)) is not None:
            wait_s = a.idle
            if msg.arbitration_id == own:
                continue  # our own frame, looped back by the multicast socket
            d = codec.classify(msg)
            if d.name == "SENSOR_POS" and d.values is not None:
                pos = d.values["Position"]
            elif d.name == "SENSOR_AUX" and pos is not None:
                u = float(np.clip(1e-4 - 0.05 * pos, -1.0, 1.0))
                bus.send(codec.encode("VALVE_CMD", {"CurrentSetpoint": u, "Enable": 1}))
                answered += 1
                pos = None
                if answered == 10 and not a.no_bad:
                    data = bytearray(codec.encode("VALVE_CMD", {"CurrentSetpoint": u}).data)
                    data[0] ^= 0xFF
                    bus.send(can.Message(arbitration_id=own, data=bytes(data), is_extended_id=False))
                    bad += 1
    finally:
        bus.shutdown()
    counts = {v.name: n for v, n in codec.counts.items()}
    print(json.dumps({"answered": answered, "bad_sent": bad, "received": counts}), flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
