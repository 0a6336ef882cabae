"""``ehpss-hil check-config FILE…``: validate configs and scenarios, one summary line each."""

from __future__ import annotations

import argparse
import sys
from pathlib import Path

from ..config import load_controller_config, load_emulator_config
from ..errors import ConfigError
from ..physics.params import load_params
from ..scenario import Scenario, load_scenario
from ..schema import load_yaml

NAME = "check-config"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("files", nargs="+", type=Path, help="YAML files (kind detected by content)")


def _kind(path: Path) -> str:
    data = load_yaml(path)
    if isinstance(data, dict):
        if "events" in data or "duration_s" in data:
            return "scenario"
        if "plant" in data or ("controller" in data and "bus" not in data):
            return "params"
        if "command_timeout_s" in data or "truth" in data or "fault_inject" in data \
                or "emulator" in path.name:
            return "emulator"
    return "controller"


def _loss_text(s: Scenario) -> str:
    """``0.05``, or ``sensor 0.05 command 0.2`` when the directions differ (at k = 0)."""
    loss = s.initial_loss
    if loss.sensor == loss.command:
        return f"{loss.sensor:g}"
    return f"sensor {loss.sensor:g} command {loss.command:g}"


def summarize(path: Path) -> str:
    """Load ``path`` as whatever it is and return a one-line summary (raises ConfigError)."""
    kind = _kind(path)
    if kind == "scenario":
        s = load_scenario(path)
        return (f"scenario {s.name}: {s.duration_s:g} s at {1 / s.sample_time_s:g} Hz, "
                f"{s.reference.kind} {s.reference.amplitude_m * 1e3:g} mm, {len(s.events)} events, "
                f"loss {_loss_text(s)}, delay {s.transport_delay_samples}")
    if kind == "params":
        p = load_params(path)
        return (f"params: K_c {p.plant.velocity_gain_1_s:.4g} 1/s, K_f {p.controller.k_f:g}, "
                f"K_p {p.controller.k_p:g}, K_i {p.controller.k_i:g}, K_a {p.controller.k_a:g}")
    if kind == "emulator":
        e = load_emulator_config(path)
        return (f"emulator: {e.bus.interface}:{e.bus.channel} at {e.rate_hz:g} Hz, {e.mode}, "
                f"command timeout {e.command_timeout_s * 1e3:g} ms, truth {e.truth}")
    c = load_controller_config(path)
    return (f"controller: {c.bus.interface}:{c.bus.channel} at {c.rate_hz:g} Hz, mode {c.mode}, "
            f"watchdog {c.watchdog.timeout_cycles} cycles -> {c.watchdog.failsafe}")


def run(args: argparse.Namespace) -> int:
    status = 0
    for f in args.files:
        try:
            print(f"{f}: OK: {summarize(f)}")
        except ConfigError as exc:
            print(f"{f}: ERROR: {exc}", file=sys.stderr)
            status = 2
    return status
