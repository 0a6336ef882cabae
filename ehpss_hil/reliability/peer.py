"""A scripted sensor peer: SENSOR_POS/SENSOR_AUX pairs with duplicates, reordering and bursts.

Run inside the trial's private namespace (``python -m ehpss_hil.reliability.peer``) against a
controller process with the probe law (:mod:`.probe`). Sample i is sent as position
``i × POSITION_STEP_M``; one schedule tick per millisecond on an absolute-deadline grid. Tick kinds
(seeded): ``normal`` [i]; ``dup`` [i, i] (the copy: 2 REPEATED frames); ``late_dup`` [i−1]
alone, a millisecond after the original (2 REPEATED); ``reorder`` [i+1] then [i] in the next
tick (i arrives late: 2 WRONG_SEQUENCE; i+1 after a gap: 2 OK_SOME_LOST); ``burst``
[i … i+K−1] with K 10–30 back to back (all OK); ``dup_burst`` [i]×5 (8 REPEATED). Every frame
sent is written to a candump file (``--sent``) and the counts by construction to a JSON summary
(``--summary``).
"""

from __future__ import annotations

import argparse
import json
import random
import sys
import time
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import can

from ..bus import open_bus
from ..canlog import format_line
from ..codec import FrameCodec
from ..config import BusConfig
from .probe import POSITION_STEP_M

#: tick kind → probability
TICKS = {"normal": 0.78, "dup": 0.06, "late_dup": 0.04, "reorder": 0.06, "burst": 0.03, "dup_burst": 0.03}


@dataclass
class Schedule:
    """Ticks of sample numbers (each one pair of frames) and what they must be classified as."""

    ticks: list[list[int]] = field(default_factory=list)
    kinds: Counter[str] = field(default_factory=Counter)
    #: samples that only ever arrive out of order (never usable)
    late: set[int] = field(default_factory=set)

    @property
    def expected(self) -> dict[str, int]:
        """Verdict counts any correct receiver gives these frames (both IDs together)."""
        pairs = sum(len(t) for t in self.ticks)
        rep = 2 * (self.kinds["dup"] + self.kinds["late_dup"] + 4 * self.kinds["dup_burst"])
        wrong = 2 * self.kinds["reorder"]
        return {
            "OK": 2 * pairs - rep - 2 * wrong,
            "OK_SOME_LOST": wrong,
            "REPEATED": rep,
            "WRONG_SEQUENCE": wrong,
        }


def make_schedule(n_samples: int, seed: int) -> Schedule:
    """At least ``n_samples`` distinct samples (numbered from 1) in seeded ticks."""
    r = random.Random(seed)
    sch = Schedule()
    kinds, weights = list(TICKS), list(TICKS.values())
    i = 1
    while i <= n_samples:
        kind = r.choices(kinds, weights)[0]
        if kind in ("late_dup", "reorder") and i == 1:
            kind = "normal"  # the first frame of an ID is accepted whatever its counter
        ticks = {
            "normal": [[i]],
            "dup": [[i, i]],
            "late_dup": [[i - 1]],
            "reorder": [[i + 1], [i]],
            "dup_burst": [[i] * 5],
        }.get(kind)
        if ticks is None:  # burst
            ticks = [list(range(i, i + r.randint(10, 30)))]
        if kind == "reorder":
            sch.late.add(i)
        sch.ticks.extend(ticks)
        sch.kinds[kind] += 1
        i = max(max(t) for t in ticks) + 1
    return sch


def _frames(codec: FrameCodec, i: int) -> tuple[bytes, bytes]:
    """The pair for sample i (counter = i mod 16, so a resend is an exact duplicate)."""
    pos = codec.encode("SENSOR_POS", {"Position": i * POSITION_STEP_M, "Spool": 0.0}, counter=i & 0xF).data
    aux = codec.encode("SENSOR_AUX", {"LoadPressure": 0.0, "CoilCurrent": 0.0}, counter=i & 0xF).data
    return bytes(pos), bytes(aux)


def play(sch: Schedule, bus_cfg: BusConfig, sent_path: Path, period_s: float = 1e-3) -> int:
    """Send the schedule on the bus at one tick per ``period_s``; returns frames sent."""
    codec = FrameCodec()
    ids = codec.can_id("SENSOR_POS"), codec.can_id("SENSOR_AUX")
    bus = open_bus(bus_cfg)
    n = 0
    try:
        time.sleep(0.2)  # the receiver's socket and ours are joined
        with open(sent_path, "w") as log:
            nxt = time.monotonic()
            for tick in sch.ticks:
                for i in tick:
                    for can_id, data in zip(ids, _frames(codec, i), strict=True):
                        msg = can.Message(
                            arbitration_id=can_id, data=data, is_extended_id=False, timestamp=time.time()
                        )
                        bus.send(msg)
                        log.write(
                            format_line(
                                (msg.timestamp, can_id, False, False, False, False, False, False, 8, data),
                                "can0",
                            )
                        )
                        n += 1
                nxt += period_s
                time.sleep(max(0.0, nxt - time.monotonic()))
        time.sleep(0.2)
    finally:
        bus.shutdown()
    return n


def main(argv: list[str] | None = None) -> int:
    p = argparse.ArgumentParser(prog="ehpss-hil-peer", description=__doc__.split("\n")[0])
    p.add_argument("--samples", type=int, default=2000)
    p.add_argument("--seed", type=int, default=1)
    p.add_argument("--sent", type=Path, required=True, help="candump file of the frames sent")
    p.add_argument("--summary", type=Path, required=True, help="JSON counts by construction")
    p.add_argument("--channel", default=BusConfig().channel)
    p.add_argument("--port", type=int, default=BusConfig().port)
    a = p.parse_args(argv)
    sch = make_schedule(a.samples, a.seed)
    n = play(sch, BusConfig(channel=a.channel, port=a.port), a.sent)
    a.summary.write_text(
        json.dumps(
            {"frames": n, "kinds": dict(sch.kinds), "expected": sch.expected, "late": sorted(sch.late)}
        )
    )
    print(f"peer: {n} frames sent", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
