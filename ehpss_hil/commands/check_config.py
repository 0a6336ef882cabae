"""``ehpss-hil check-config FILE…``: validate configs, scenarios and campaigns, one summary line each.

A file is read once. Beyond the schema, each is prepared as far as its program goes before
opening a bus (parameters, DBC with the ID layout, trajectory file, the control law or the plant
emulation built), so a file accepted here is one the programs run with.
"""

from __future__ import annotations

import argparse
import sys
from pathlib import Path
from typing import Any

from ..config import ControllerConfig, DbcMap, EmulatorConfig, load_controller_config, load_emulator_config
from ..errors import ConfigError, EhpssError, one_line
from ..physics.load import load_params
from ..physics.params import Params
from ..scenario import Scenario, load_scenario
from ..schema import load_yaml

NAME = "check-config"


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("files", nargs="+", type=Path, help="YAML files (kind detected by content)")


def _kind(data: Any, path: Path) -> str:
    if isinstance(data, dict):
        if "samples" in data and "base" in data:
            return "campaign"
        if "events" in data or "duration_s" in data:
            return "scenario"
        if "plant" in data or ("controller" in data and "bus" not in data):
            return "params"
        if (
            "command_timeout_s" in data
            or "truth" in data
            or "fault_inject" in data
            or "emulator" in path.name
        ):
            return "emulator"
    return "controller"


def _loss_text(s: Scenario) -> str:
    """``0.05``, or ``sensor 0.05 command 0.2`` when the directions differ (at k = 0)."""
    loss = s.initial_loss
    if loss.sensor == loss.command:
        return f"{loss.sensor:g}"
    return f"sensor {loss.sensor:g} command {loss.command:g}"


def _prepare_scenario(s: Scenario, params: Params) -> None:
    """Build what the simulator builds from a scenario (the plant emulation, the default control
    law with its reference and sample time)."""
    from ..control.registry import make_controller
    from ..emulation import PlantEmulation

    PlantEmulation(params, s)
    make_controller("mmac", params, s.sample_time_s, None, s.reference)


def _prepare_controller(path: Path, c: ControllerConfig) -> None:
    """What ``ehpss-hil controller`` does with its config before opening the bus."""
    from ..daemon import default_factory, loop_options
    from ..protocol.travel import check_controller_travel
    from ..runtime.frameio import process_codec

    params = load_params(c.params or None)
    plant = params.plant
    codec = process_codec(
        c.dbc, c.ids, str(path), c.protocol, c.dbc_map, c.nodes, plant.spool_stroke_m, plant.stroke_current_a
    )
    check_controller_travel(codec, c, str(path))
    loop_options(c)
    default_factory(c.mode, params, 1.0 / c.rate_hz, c)


def _prepare_emulator(path: Path, e: EmulatorConfig) -> None:
    """What ``firmware-sim`` does with its config before opening the bus."""
    from ..runtime.frameio import process_codec

    params = load_params(e.params or None)
    if e.protocol == "cia408":
        from ..protocol.cia408.check import check_nodes

        check_nodes(e.nodes, str(path))
    else:
        process_codec(
            e.dbc, e.ids, str(path), e.protocol, e.dbc_map, stroke_current_a=params.plant.stroke_current_a
        )
    if e.scenario:
        _prepare_scenario(load_scenario(e.scenario), params)


def _protocol_text(protocol: str, m: DbcMap | None) -> str:
    """``, protocol dbc-map (vendor.dbc, E2E p02)`` for a mapped profile; nothing for native."""
    if m is None:
        return ""
    return f", protocol {protocol} ({Path(m.dbc).name}, E2E {m.e2e.profile})"


def summarize(path: Path) -> str:
    """Load ``path`` as whatever it is and return a one-line summary (raises ConfigError
    naming ``path``)."""
    try:
        return _summarize(path)
    except ConfigError as exc:
        if exc.source:
            raise
        raise ConfigError(str(path), exc.key_path, exc.reason) from exc


def _summarize(path: Path) -> str:
    data = load_yaml(path)
    kind = _kind(data, path)
    if kind == "scenario":
        s = load_scenario(path, data)
        _prepare_scenario(s, load_params())
        return (
            f"scenario {s.name}: {s.duration_s:g} s at {1 / s.sample_time_s:g} Hz, "
            f"{s.reference.kind} {s.reference.amplitude_m * 1e3:g} mm, {len(s.events)} events, "
            f"loss {_loss_text(s)}, delay {s.transport_delay_samples}"
            + ("" if s.plant.is_nominal else f", plant {s.plant.describe()}")
        )
    if kind == "campaign":
        return _summarize_campaign(path, data)
    if kind == "params":
        p = load_params(path)  # (few bytes: read again rather than a second entry point)
        _prepare_scenario(Scenario(name="check", duration_s=1.0), p)
        return (
            f"params: K_c {p.plant.velocity_gain_1_s:.4g} 1/s, K_f {p.controller.k_f:g}, "
            f"K_p {p.controller.k_p:g}, K_i {p.controller.k_i:g}, K_a {p.controller.k_a:g}"
        )
    if kind == "emulator":
        e = load_emulator_config(path, data)
        _prepare_emulator(path, e)
        return (
            f"emulator: {e.bus.interface}:{e.bus.channel} at {e.rate_hz:g} Hz, {e.mode}, "
            f"command timeout {e.command_timeout_s * 1e3:g} ms, truth {e.truth}"
            + _protocol_text(e.protocol, e.dbc_map)
            + (
                f", protocol cia408 (valve node {e.nodes.valve_node}, encoder node {e.nodes.encoder_node})"
                if e.protocol == "cia408"
                else ""
            )
        )
    c = load_controller_config(path, data)
    _prepare_controller(path, c)
    return (
        f"controller: {c.bus.interface}:{c.bus.channel} at {c.rate_hz:g} Hz, mode {c.mode}, "
        f"watchdog {c.watchdog.timeout_cycles} cycles -> {c.watchdog.failsafe}"
        + _protocol_text(c.protocol, c.dbc_map)
        + (_master_text(c) if c.protocol == "cia408" else "")
    )


def _master_text(c: ControllerConfig) -> str:
    """``, protocol cia408 master (valve node 32, position from encoder node 33, SYNC produced)``."""
    n = c.nodes
    source = "the valve" if n.position_source == "valve" else f"encoder node {n.encoder_node}"
    sync = "produced" if n.sync == "produce" else "followed"
    return f", protocol cia408 master (valve node {n.valve_node}, position from {source}, SYNC {sync})"


#: runs of a campaign whose scenarios check-config builds (the cost does not grow with samples)
CHECKED_CAMPAIGN_RUNS = 16


def _summarize_campaign(path: Path, data: Any) -> str:
    """A campaign file with its base scenario and the scenarios of a draw of
    :data:`CHECKED_CAMPAIGN_RUNS` runs built."""
    from ..campaign.sampling import plan_runs
    from ..campaign.spec import load_campaign

    c = load_campaign(path, data)
    plan_runs(c, CHECKED_CAMPAIGN_RUNS)
    kinds = [k for k, w in c.spec.faults.kinds.weights().items() if w > 0]
    lo, hi = c.spec.faults.count
    return (
        f"campaign {c.spec.name}: {c.spec.samples} runs of {c.duration_s:g} s ({c.spec.sampler}), "
        f"{lo}-{hi} of {', '.join(kinds)}, modes {', '.join(c.spec.modes)}"
        + (f", model error on {', '.join(me.ranges())}" if (me := c.spec.model_error) is not None else "")
    )


def run(args: argparse.Namespace) -> int:
    status = 0
    for f in args.files:
        try:
            print(one_line(f"{f}: OK: {summarize(f)}"))
        except EhpssError as exc:  # ConfigError; a model or DBC that cannot be built from it
            print(one_line(f"{f}: ERROR: {exc}"), file=sys.stderr)
            status = 2
    return status
