"""What run produced a log: its reference, sample time, mode, tuning and parameters.

Looked up, first hit wins, in: the caller's scenario; the log's sidecar; then, in an
``ehpss-hil run`` directory (one holding ``run.json``), ``run.json`` and the other logs' sidecars. In each, a
``scenario`` (a mapping, a YAML path or a scenario name found in ``scenarios/``) or
``scenario_path``, then a ``config`` (a mapping like ``controller.yaml``, or the path of a
controller/emulator YAML), then top-level ``reference``/``rate_hz``/``mode``/``params``; and
whether the run was lockstep (:func:`~ehpss_hil.canlog.sidecar.lockstep_of`).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from .. import PROJECT_ROOT
from ..canlog.sidecar import lockstep_of
from ..config import (
    ControllerConfig,
    SetpointPolicy,
    load_controller_config,
    load_emulator_config,
)
from ..control.tuning import ControlTuning
from ..errors import ConfigError
from ..scenario import Reference, Scenario, load_scenario
from ..schema import build


@dataclass
class RunInfo:
    """The run's reference and controller setup as far as the metadata tells (SI: Ts in s)."""

    scenario: Scenario | None = None
    reference: Reference | None = None
    ts_s: float | None = None
    mode: str | None = None
    tuning: ControlTuning | None = None
    setpoint: SetpointPolicy | None = None
    params_path: str | None = None
    #: True: a lockstep run (the wall clock does not follow the cycles); None: not recorded
    lockstep: bool | None = None
    sources: list[str] = field(default_factory=list)


def _reference_keys(ref: Any) -> Any:
    """A sidecar's reference mapping without the loaded table (``asdict`` writes it as text)."""
    return {k: v for k, v in ref.items() if k != "table"} if isinstance(ref, dict) else ref


def scenario_from(value: Any, log_dir: Path) -> Scenario | None:
    """A scenario from a sidecar value: mapping, YAML path, or name of a shipped scenario."""
    if isinstance(value, dict):
        if value.get("path"):
            return scenario_from(str(value["path"]), log_dir)
        clean = {k: v for k, v in value.items() if k != "base_dir"}
        if "reference" in clean:
            clean["reference"] = _reference_keys(clean["reference"])
        if isinstance(clean.get("events"), list):
            clean["events"] = [
                {k: v for k, v in ev.items() if v is not None}
                for ev in clean["events"]
                if isinstance(ev, dict)
            ]
        return build(Scenario, clean, "sidecar", "scenario")
    if not isinstance(value, str) or not value:
        return None
    for p in (Path(value), log_dir / value, PROJECT_ROOT / "scenarios" / f"{value}.yaml"):
        if p.suffix in (".yaml", ".yml") and p.is_file():
            return load_scenario(p)
    for p in sorted((PROJECT_ROOT / "scenarios").glob("*.yaml")):
        try:
            sc = load_scenario(p)
        except ConfigError:
            continue
        if sc.name == value:
            return sc
    return None


def _from_config_file(path: Path, info: RunInfo) -> None:
    """Fill ``info`` from a controller.yaml or an emulator.yaml (whichever it is)."""
    try:
        c: ControllerConfig = load_controller_config(path)
    except ConfigError:
        try:
            e = load_emulator_config(path)
        except ConfigError:
            return
        if info.scenario is None and e.scenario and Path(e.scenario).is_file():
            info.scenario = load_scenario(e.scenario)
        info.ts_s = info.ts_s or 1.0 / e.rate_hz
        if info.lockstep is None:
            info.lockstep = e.mode == "lockstep"
        return
    info.reference = info.reference or c.reference
    info.ts_s = info.ts_s or 1.0 / c.rate_hz
    info.mode = info.mode or c.mode
    info.tuning = info.tuning or c.tuning
    info.setpoint = info.setpoint or c.setpoint
    info.params_path = info.params_path or c.params or None


def _from_mapping(side: dict[str, Any], log_dir: Path, info: RunInfo) -> None:
    """Fill what is still missing in ``info`` from one sidecar-like mapping."""
    if info.lockstep is None:
        info.lockstep = lockstep_of(side)
    if info.scenario is None:
        info.scenario = scenario_from(side.get("scenario"), log_dir) or scenario_from(
            side.get("scenario_path"), log_dir
        )
    cfg = side.get("config")
    if isinstance(cfg, str) and Path(cfg).is_file():
        _from_config_file(Path(cfg), info)
    cfg_d: dict[str, Any] = cfg if isinstance(cfg, dict) else {}
    ref_d = _reference_keys(cfg_d.get("reference", side.get("reference")))
    if info.reference is None and isinstance(ref_d, dict):
        info.reference = build(Reference, ref_d, "sidecar", "reference")
    rate = cfg_d.get("rate_hz", side.get("rate_hz"))
    if info.ts_s is None and isinstance(rate, (int, float)) and rate > 0:
        info.ts_s = 1.0 / float(rate)
    mode = cfg_d.get("mode", side.get("mode"))
    if info.mode is None and isinstance(mode, str) and mode not in ("realtime", "lockstep"):
        info.mode = mode
    tun = cfg_d.get("tuning")
    if info.tuning is None and isinstance(tun, dict):
        info.tuning = build(ControlTuning, tun, "sidecar", "config.tuning")
    sp = cfg_d.get("setpoint")
    if info.setpoint is None and isinstance(sp, dict):
        info.setpoint = build(SetpointPolicy, sp, "sidecar", "config.setpoint")
    p = cfg_d.get("params", side.get("params"))
    if info.params_path is None and isinstance(p, str) and p and Path(p).is_file():
        info.params_path = p


def _neighbours(log_dir: Path, own: Path | None) -> list[tuple[str, dict[str, Any]]]:
    """``run.json`` and the other sidecars of an ``ehpss-hil run`` directory (one holding a
    ``run.json``; elsewhere unrelated logs may share a directory, so nothing is borrowed)."""
    if not (log_dir / "run.json").is_file():
        return []
    out = []
    for f in sorted(log_dir.glob("*.json")):
        if own is not None and f.name == own.name + ".json":
            continue
        if not (f.name == "run.json" or f.name.endswith(".log.json")):
            continue
        try:
            data = json.loads(f.read_text(encoding="utf-8"))
        except (OSError, ValueError):
            continue
        if isinstance(data, dict):
            out.append((f.name, data))
    return out


def run_info(
    side: dict[str, Any] | None, log_dir: Path, scenario: Scenario | None = None, log: Path | None = None
) -> RunInfo:
    """Everything the metadata around a log tells about its run (see the module docstring)."""
    info = RunInfo(scenario=scenario)
    if scenario is not None:
        info.sources.append("--scenario")
    sources = [("sidecar", side or {}), *_neighbours(log_dir, log)]
    for name, data in sources:
        before = (info.scenario, info.reference, info.ts_s, info.mode)
        _from_mapping(data, log_dir, info)
        if (info.scenario, info.reference, info.ts_s, info.mode) != before:
            info.sources.append(name)
    if info.scenario is not None:
        info.reference = info.scenario.reference
        info.ts_s = info.scenario.sample_time_s
    return info


def reference_of(
    side: dict[str, Any] | None, log_dir: Path, scenario: Scenario | None = None
) -> tuple[Scenario | None, Reference | None, float | None]:
    """``(scenario, reference, Ts)`` of a run from the caller's scenario or the metadata."""
    info = run_info(side, log_dir, scenario)
    return info.scenario, info.reference, info.ts_s
