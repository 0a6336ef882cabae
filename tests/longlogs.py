"""Long bench-like logs for the streamed report's tests and measurements, written fast.

One lockstep run of exactly 65 536 samples (:func:`~ehpss_hil.sim.samplelog.write_lockstep_log`,
the fault-free scenario in NRC) is the tile: its CycleCount wraps after exactly one tile and every
1 kHz frame's E2E counter (mod 16) with it, so tiles laid one after the other (timestamps moved
on by the tile's length) read as one run of any length.
"""

from __future__ import annotations

import shutil
from dataclasses import replace
from pathlib import Path

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.scenario import load_scenario
from ehpss_hil.sim.samplelog import write_lockstep_log

#: samples of one tile: the 16-bit CycleCount's period
TILE_SAMPLES = 65_536


def tile_log(folder: Path) -> Path:
    """The tile (65.536 s at 1 kHz, fault-free, NRC), written once into ``folder``."""
    path = folder / "tile.log"
    if not path.exists():
        sc = load_scenario(PROJECT_ROOT / "scenarios" / "fault-free.yaml")
        sc = replace(sc, duration_s=TILE_SAMPLES * sc.sample_time_s)
        write_lockstep_log(sc, "nrc", path, queue_lines=8 * TILE_SAMPLES)
    return path


def long_log(tile: Path, dst: Path, samples: int) -> Path:
    """A log of ``samples`` controller samples (a whole number of tiles' worth, the last tile
    cut at its sample) with the tile's sidecar."""
    lines = tile.read_text().splitlines(keepends=True)
    stamps = [round(float(ln[1:18]) * 1e6) for ln in lines]
    period_us = round((stamps[-1] - stamps[0]) / (TILE_SAMPLES - 1))
    rest = [ln[19:] for ln in lines]
    t0 = stamps[0]
    dst.parent.mkdir(parents=True, exist_ok=True)
    with open(dst, "w") as fh:
        done = 0
        while done < samples:
            off = done * period_us
            cut = t0 + (samples - done) * period_us
            fh.write(
                "".join(
                    f"({(us + off) / 1e6:017.6f}){r}" for us, r in zip(stamps, rest, strict=True) if us < cut
                )
            )
            done += TILE_SAMPLES
    shutil.copy(tile.with_name(tile.name + ".json"), dst.with_name(dst.name + ".json"))
    return dst
