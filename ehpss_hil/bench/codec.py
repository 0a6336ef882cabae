"""``ehpss-hil bench codec``: encode / classify / E2E cost per frame (µs, p50/p99), the fast path
(precomputed bit layout + table CRC) beside the cantools + crccheck path it replaced."""

from __future__ import annotations

import argparse
import time
from collections.abc import Callable
from typing import Any

import can
import numpy as np
from cantools.autosar.end_to_end import apply_profile2_crc, check_profile2_crc

from ..codec import CounterCheck, FrameCodec
from ..codec.e2e import crc_ok, protect
from .common import Scorecard, percentiles_us, write_json

NAME = "codec"
HELP = "frame codec micro-benchmark: encode, classify, E2E — fast path beside cantools/crccheck"

_SAMPLES: dict[str, dict[str, Any]] = {
    "SENSOR_POS": {"Position": 0.00123456, "Spool": -0.00152},
    "SENSOR_AUX": {"LoadPressure": 2.3e5, "CoilCurrent": 9.2e-5, "ValveEnabled": 1},
    "VALVE_CMD": {"CurrentSetpoint": 9.2e-5, "Enable": 1, "SensorCounterEcho": 3, "CycleCount": 7},
    "CTRL_INDEX": {"ModelSlot": 5, "J_5": 0.0123, "Theta_5": 0.5},
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("-n", "--samples", type=int, default=20000, help="timed calls per figure")
    p.add_argument(
        "--sleep-us",
        type=float,
        default=0.0,
        help="sleep this long before each timed call, as a loop does between cycles "
        "(caches and predictors go cold; use fewer --samples)",
    )
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


def _time_calls(fn: Callable[[], object], n: int, sleep_s: float = 0.0) -> np.ndarray:
    out = np.empty(n)
    clock = time.perf_counter_ns
    for i in range(n):
        if sleep_s:
            time.sleep(sleep_s)
        t0 = clock()
        fn()
        out[i] = clock() - t0
    return out * 1e-9


def _cantools_encode(codec: FrameCodec, name: str, values: dict[str, Any], counter: int) -> can.Message:
    """The replaced encode: plausibility, cantools ``encode(strict=False)``, crccheck CRC."""
    msg = codec.message(name)
    if codec.check_plausible(name, values) is not None:
        raise ValueError(name)
    full = {s.name: 0 for s in msg.signals if s.multiplexer_ids is None}
    full.update(values)
    full["CRC"] = full["Counter"] = 0
    data = bytearray(msg.encode(full, scaling=True, padding=False, strict=False))
    ids = codec.data_ids(name)
    assert ids is not None
    data[1] = (data[1] & 0xF0) | counter
    out = apply_profile2_crc(bytes(data), ids[counter])
    assert out is not None
    return can.Message(
        arbitration_id=codec.can_id(name), data=bytes(out), is_extended_id=False, dlc=msg.length
    )


def _cantools_classify(codec: FrameCodec, check: CounterCheck, frame: can.Message) -> object:
    """The replaced classify: crccheck CRC, counter, cantools ``decode``, plausibility."""
    name = codec.name_of(frame.arbitration_id)
    assert name is not None
    ids = codec.data_ids(name)
    assert ids is not None
    data = bytes(frame.data)
    if not check_profile2_crc(data, ids[data[1] & 0x0F]):
        return None
    check.check(data[1])
    values = codec.message(name).decode(data, decode_choices=False, scaling=True, allow_truncated=False)
    return codec.check_plausible(name, values)  # type: ignore[arg-type]


def _operations(
    tx: FrameCodec, rx: FrameCodec, name: str, values: dict[str, Any]
) -> dict[str, tuple[Callable[[], object], Callable[[], object] | None]]:
    """operation → (fast path, cantools/crccheck path or None)."""
    frames = [tx.encode(name, values) for _ in range(16)]
    ids = tx.data_ids(name)
    assert ids is not None
    payload = bytearray(frames[0].data)
    i = iter(range(10**12))
    check = CounterCheck(3)
    return {
        "encode": (lambda: tx.encode(name, values), lambda: _cantools_encode(tx, name, values, next(i) & 15)),
        "classify": (
            lambda: rx.classify(frames[next(i) & 15]),
            lambda: _cantools_classify(rx, check, frames[next(i) & 15]),
        ),
        "quantize": (lambda: tx.quantize(name, values), None),
        "e2e_protect": (lambda: protect(payload, 5, ids), lambda: apply_profile2_crc(bytes(payload), ids[5])),
        "e2e_check": (
            lambda: crc_ok(frames[0].data, ids),
            lambda: check_profile2_crc(bytes(frames[0].data), ids[frames[0].data[1] & 15]),
        ),
    }


def measure(n: int, sleep_s: float = 0.0) -> list[dict[str, object]]:
    """Per-frame timings (µs) of each operation, fast path and (where there is one) cantools."""
    tx, rx = FrameCodec(), FrameCodec()
    rows: list[dict[str, object]] = []
    for name, values in _SAMPLES.items():
        for op, (fast, ref) in _operations(tx, rx, name, values).items():
            if op == "quantize" and tx.message(name).is_multiplexed():
                continue
            row: dict[str, object] = {"frame": name, "op": op}
            for key, fn in (("fast", fast), ("cantools", ref)):
                if fn is None:
                    continue
                _time_calls(fn, min(n, 2000))  # warm-up
                row[key] = percentiles_us(_time_calls(fn, n, sleep_s))
            rows.append(row)
    return rows


def run(args: argparse.Namespace) -> Scorecard:
    rows = measure(args.samples, args.sleep_us * 1e-6)
    print(f"{'':25} {'fast path (µs)':^27}   {'cantools/crccheck (µs)':^27}")
    print(
        f"{'frame':<12} {'operation':<12} {'p50':>8} {'p99':>8} {'p99.9':>9}   "
        f"{'p50':>8} {'p99':>8} {'p99.9':>9}  {'p50 ratio':>9}"
    )
    for r in rows:
        f: dict[str, float] = r["fast"]  # type: ignore[assignment]
        line = f"{r['frame']:<12} {r['op']:<12} {f['p50_us']:8.2f} {f['p99_us']:8.2f} {f['p999_us']:9.2f}"
        c: dict[str, float] | None = r.get("cantools")  # type: ignore[assignment]
        if c is not None:
            line += (
                f"   {c['p50_us']:8.2f} {c['p99_us']:8.2f} {c['p999_us']:9.2f}  "
                f"{c['p50_us'] / f['p50_us']:8.1f}×"
            )
        print(line)
    cold = f", a {args.sleep_us:g} µs sleep before each call" if args.sleep_us else ""
    print(
        f"({args.samples} timed calls each{cold}, time.perf_counter_ns, one core. encode = "
        "plausibility + payload + E2E + can.Message; classify = DLC + E2E CRC + counter + "
        "decode + plausibility; fast = precomputed bit layout + table CRC, equal to cantools "
        "bit for bit, tests/test_codec_layout.py)"
    )
    write_json(args.json, rows)
    return Scorecard()  # figures only: no targets
