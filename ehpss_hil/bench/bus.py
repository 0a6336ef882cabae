"""``ehpss-hil bench bus``: worst-case bus load of each protocol profile at 1 and 2 kHz on 1 Mbit/s
and 500 kbit/s (:mod:`ehpss_hil.protocol.busload`) against
:data:`~ehpss_hil.protocol.busload.BUS_LOAD_LIMIT`. Computed, not measured: bits per frame with
worst-case stuffing × the frames a deployment sends. The cell of each config's own ``rate_hz``
and ``bus.bitrate`` is its target (PASS/FAIL, the exit code); the other cells say what would fit
(``fits``/``over``)."""

from __future__ import annotations

import argparse
from pathlib import Path
from typing import Any

from ..config import load_controller_config
from ..orchestrate import PROJECT_ROOT
from ..protocol.busload import BUS_LOAD_LIMIT, PERIODIC_FRAMES, FrameRate, frame_bits, load
from ..sim.lockstep import config_codec
from .common import Scorecard, write_json

NAME = "bus"
HELP = "worst-case CAN bus load of each protocol profile at 1/2 kHz on 1 Mbit/s and 500 kbit/s"

RATES_HZ = (1000.0, 2000.0)
BITRATES_BPS = (1_000_000, 500_000)
#: models reported in CTRL_INDEX after each CTRL_STATUS, per mode (the controllers' index slots)
INDEX_FRAMES = {"nrc": 0, "smac": 1, "mmac-paper": 5, "mmac": 9}
#: CTRL_STATS rate (Hz): the controller loop's fixed stats rate
STATS_RATE_HZ = 10.0
#: the emulator's heartbeat rate (Hz), configs/emulator.yaml
EMULATOR_HEARTBEAT_HZ = 10.0
DEFAULT_CONFIGS = (
    "configs/controller.yaml",
    "configs/controller-vendor.yaml",
    "configs/controller-cia408.yaml",
)


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--config",
        action="append",
        metavar="CONTROLLER.yaml",
        help="a controller config whose profile to rate (repeatable; default the shipped native and vendor)",
    )
    p.add_argument(
        "--mode", default="mmac", choices=sorted(INDEX_FRAMES), help="controller mode (CTRL_INDEX frames)"
    )
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


def profile_frames(config: str, rate_hz: float, mode: str, extended: bool | None = None) -> list[FrameRate]:
    """The frames a deployment of controller config ``config`` puts on the bus per second at
    ``rate_hz``; ``extended`` forces the valve frames' ID format (None: the profile's). Under
    ``cia408`` the valve frames are the PDOs, with the master's SYNC each period (``sync:
    produce``), CTRL_DEVICE beside CTRL_STATUS, and the nodes' CANopen heartbeats instead of the
    emulator's."""
    cfg = load_controller_config(config)
    codec = config_codec(config)
    cia408 = cfg.protocol == "cia408"
    periodic = [*PERIODIC_FRAMES, *(["SYNC"] if cia408 and cfg.nodes.sync == "produce" else [])]
    out = []
    for name in periodic:
        shape = codec.shape(name)
        ext = shape.is_extended_id if extended is None else extended
        out.append(FrameRate(name, shape.dlc, ext, rate_hz))
    status = cfg.status_rate_hz
    for name, hz in (
        ("CTRL_STATUS", status),
        ("CTRL_INDEX", status * INDEX_FRAMES[mode]),
        ("CTRL_STATS", STATS_RATE_HZ),
        ("HEARTBEAT_CTRL", cfg.heartbeat_rate_hz),
        *((("CTRL_DEVICE", status),) if cia408 else (("HEARTBEAT_EMU", EMULATOR_HEARTBEAT_HZ),)),
    ):
        if hz > 0:
            out.append(FrameRate(name, codec.shape(name).dlc, False, hz))
    if cia408 and cfg.nodes.heartbeat_time_ms > 0:
        nodes = 2 if cfg.nodes.position_source == "encoder" else 1
        hz = 1000.0 / cfg.nodes.heartbeat_time_ms
        out.extend(FrameRate("node heartbeat", 1, False, hz) for _ in range(nodes))
    return out


def _profiles(configs: list[str]) -> list[tuple[str, str, bool | None]]:
    """(label, config, forced ID format): each config, and a mapped one again with 29-bit IDs."""
    out: list[tuple[str, str, bool | None]] = []
    for c in configs:
        cfg = load_controller_config(c)
        dbc = Path(cfg.dbc_map.dbc if cfg.dbc_map else cfg.dbc or "ehpss.dbc").name
        label = f"{cfg.protocol} ({'CiA 408/406 PDOs' if cfg.protocol == 'cia408' else dbc})"
        out.append((label, c, None))
        if cfg.dbc_map is not None:
            out.append((f"{label}, 29-bit IDs", c, True))
    return out


def _cell(card: Scorecard, x: float, own: bool, what: str) -> str:
    """The load and its verdict: PASS/FAIL for a config's own rate and bit rate (counted),
    fits/over for the others."""
    ok = x <= BUS_LOAD_LIMIT
    verdict = card.mark(ok, what) if own else ("fits" if ok else "over")
    return f"{x:6.1%} {verdict}"


def run(args: argparse.Namespace) -> Scorecard:
    card = Scorecard()
    configs = args.config or [str(PROJECT_ROOT / c) for c in DEFAULT_CONFIGS]
    rows: list[dict[str, Any]] = []
    print(
        f"worst-case stuffing: 8-byte frame {frame_bits(8, False)} bits (11-bit ID), "
        f"{frame_bits(8, True)} bits (29-bit ID); limit {BUS_LOAD_LIMIT:.0%}; mode {args.mode}"
    )
    print(
        f"{'profile':44} {'rate':>6} {'valve bit/s':>12} {'all bit/s':>11} "
        f"{'1 Mbit/s':>14} {'500 kbit/s':>14}"
    )
    for label, config, ext in _profiles(configs):
        cfg = load_controller_config(config)
        for rate in RATES_HZ:
            frames = profile_frames(config, rate, args.mode, ext)
            valve = sum(f.bits_per_s for f in frames if f.name in (*PERIODIC_FRAMES, "SYNC"))
            total = sum(f.bits_per_s for f in frames)
            cells = []
            for bps in BITRATES_BPS:
                x = load(frames, bps)
                own = rate == cfg.rate_hz and bps == cfg.bus.bitrate
                what = f"{label} {rate:g} Hz on {bps / 1e6:g} Mbit/s: {x:.1%}"
                cells.append(_cell(card, x, own, what))
                rows.append(
                    {
                        "profile": label,
                        "rate_hz": rate,
                        "bitrate_bps": bps,
                        "load": x,
                        "fits": x <= BUS_LOAD_LIMIT,
                        "target": own,
                    }
                )
            print(f"{label:44} {rate:5.0f}  {valve:12.0f} {total:11.0f} {cells[0]:>14} {cells[1]:>14}")
        sizes = ", ".join(
            f"{f.name} {f.data_bytes} B {frame_bits(f.data_bytes, f.extended)} bit"
            for f in frames
            if f.name in (*PERIODIC_FRAMES, "SYNC")
        )
        print(f"{'':44} ({sizes})")
    fits = [
        f"{r['profile']} {r['rate_hz'] / 1e3:g} kHz on {r['bitrate_bps'] / 1e6:g} Mbit/s"
        for r in rows
        if r["fits"]
    ]
    print(f"fits within {BUS_LOAD_LIMIT:.0%}: " + ("; ".join(fits) if fits else "nothing"))
    print("PASS/FAIL: each config's own rate_hz and bus.bitrate (the target); fits/over: the others")
    write_json(args.json, rows)
    return card
