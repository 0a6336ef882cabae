"""``ehpss-hil bench codec``: encode / decode / E2E cost per frame (µs, p50/p99)."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable

import numpy as np

from ..codec import FrameCodec
from ..codec.e2e import crc_ok, protect
from .common import percentiles_us, write_json

NAME = "codec"
HELP = "frame codec micro-benchmark: encode, classify (decode + E2E + plausibility), CRC alone"

_SAMPLES = {
    "SENSOR_POS": {"Position": 0.00123456, "Spool": -0.00152},
    "SENSOR_AUX": {"LoadPressure": 2.3e5, "CoilCurrent": 9.2e-5, "ValveEnabled": 1},
    "VALVE_CMD": {"CurrentSetpoint": 9.2e-5, "Enable": 1, "SensorCounterEcho": 3, "CycleCount": 7},
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-n", "--samples", type=int, default=20000, help="timed calls per figure")
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


def _time_calls(fn: Callable[[], object], n: int) -> np.ndarray:
    out = np.empty(n)
    clock = time.perf_counter_ns
    for i in range(n):
        t0 = clock()
        fn()
        out[i] = clock() - t0
    return out * 1e-9


def measure(n: int) -> list[dict[str, object]]:
    """Per-frame timings (µs) of encode, classify, quantize and the bare E2E protect/check."""
    tx, rx = FrameCodec(), FrameCodec()
    rows: list[dict[str, object]] = []
    for name, values in _SAMPLES.items():
        for op, fn in _operations(tx, rx, name, values).items():
            _time_calls(fn, min(n, 2000))  # warm-up
            rows.append({"frame": name, "op": op, **percentiles_us(_time_calls(fn, n))})
    return rows


def _operations(tx: FrameCodec, rx: FrameCodec, name: str,
                values: dict[str, float]) -> dict[str, Callable[[], object]]:
    frames = [tx.encode(name, values) for _ in range(16)]
    ids = tx.data_ids(name)
    assert ids is not None
    payload = bytearray(frames[0].data)
    i = iter(range(10**12))
    return {
        "encode": lambda: tx.encode(name, values),
        "classify": lambda: rx.classify(frames[next(i) & 15]),
        "quantize": lambda: tx.quantize(name, values),
        "e2e_protect": lambda: protect(payload, 5, ids),
        "e2e_check": lambda: crc_ok(frames[0].data, ids),
    }


def run(args: argparse.Namespace) -> int:
    rows = measure(args.samples)
    print(f"{'frame':<12} {'operation':<12} {'p50 µs':>8} {'p99 µs':>8} {'p99.9 µs':>9} {'max µs':>8}")
    for r in rows:
        print(f"{r['frame']:<12} {r['op']:<12} {r['p50_us']:8.2f} {r['p99_us']:8.2f} "
              f"{r['p999_us']:9.2f} {r['max_us']:8.1f}")
    print(f"({args.samples} timed calls each, time.perf_counter_ns, one core; classify = "
          "DLC + E2E CRC + counter + cantools decode + plausibility)")
    write_json(args.json, rows)
    return 0
