"""Bad configs and scenarios: every key of ``configs/controller.yaml``, ``configs/emulator.yaml``
and a scenario made wrong in turn, each given to a real process.

One wrong value per key — numbers out of their range, a wrong type for strings and booleans, an
unknown choice for enumerations, plus files that do not exist or cannot be written for the path
keys and one unknown key per file and per section. Each process (controller, or emulator with the
scenario) must exit 2 with exactly one line of output naming the key path; all of them run in one
private namespace beside a bus logger, which must see no frame at all (nothing reached the bus).
"""

from __future__ import annotations

import copy
import time
from collections.abc import Iterator
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import yaml

from .. import PROJECT_ROOT
from ..orchestrate import write_config
from ..schema import load_yaml
from .logcheck import read_candump
from .procs import CONTROLLER_YAML, EMULATOR_YAML, PY, Child, Trial

SCENARIO = PROJECT_ROOT / "scenarios" / "case1-loe.yaml"
#: keys that name files: wrong values beyond the type error
_PATH_KEYS = ("params", "dbc", "scenario", "log.path")
_ENUMS = ("bus.interface", "mode", "reference.kind", "watchdog.failsafe")

Path_ = tuple[str | int, ...]


@dataclass(frozen=True)
class Mutation:
    """``target`` ("controller" | "emulator" | "scenario") with ``key`` set to ``value``."""

    target: str
    key: Path_
    value: Any
    why: str  # "range" | "type" | "choice" | "file" | "unknown key"

    @property
    def key_path(self) -> str:
        """``events[2].k_loe`` style."""
        out = ""
        for k in self.key:
            out += f"[{k}]" if isinstance(k, int) else (f".{k}" if out else k)
        return out


@dataclass
class BadResult:
    """What the process did with one mutation."""

    mutation: Mutation
    exit_code: int | None
    lines: list[str]

    @property
    def names_key(self) -> bool:
        """The message names the key path as its own field (``…yaml: watchdog.failsafe: …``)."""
        k = self.mutation.key_path
        return any(f": {k}{end}" in ln for ln in self.lines for end in (": ", " ("))

    @property
    def ok(self) -> bool:
        """Exit 2, one line, naming the key path."""
        return self.exit_code == 2 and len(self.lines) == 1 and self.names_key


def _leaves(data: Any, prefix: Path_ = ()) -> Iterator[tuple[Path_, Any]]:
    if isinstance(data, dict):
        for k, v in data.items():
            yield from _leaves(v, (*prefix, k))
    elif isinstance(data, list):
        for i, v in enumerate(data):
            yield from _leaves(v, (*prefix, i))
    else:
        yield prefix, data


def _wrong(target: str, key: Path_, value: Any, tmp: Path) -> list[Mutation]:
    """The wrong values for one key."""
    dotted = ".".join(str(k) for k in key)
    if isinstance(value, bool):
        return [Mutation(target, key, "maybe", "type")]
    if isinstance(value, int):
        return [Mutation(target, key, -(10**12), "range")]
    if isinstance(value, float):
        return [Mutation(target, key, -1e12, "range")]
    if dotted in _ENUMS:
        return [Mutation(target, key, "bogus", "choice")]
    if dotted == "bus.channel":
        return [Mutation(target, key, "224.0.0.1", "range")]  # a group that would leave the host
    out = [Mutation(target, key, [1, 2], "type")]
    if dotted in _PATH_KEYS:
        not_dir = tmp / "not-a-directory"
        not_dir.touch()
        bad = str(not_dir / "x.log") if dotted == "log.path" else str(tmp / f"missing-{dotted}")
        out.append(Mutation(target, key, bad, "file"))
    return out


def base_scenario() -> dict[str, Any]:
    """Case 1 with every loss key set (top level and in an event)."""
    data = load_yaml(SCENARIO)
    data["sensor_frame_loss"] = 0.01
    data["command_frame_loss"] = 0.02
    data["events"].append({"t_s": 3.0, "sensor_frame_loss": 0.05, "command_frame_loss": 0.1})
    return data


def mutations(tmp: Path) -> list[Mutation]:
    """Every key of the three files made wrong in turn, plus unknown keys (wrong file paths
    point into ``tmp``)."""
    tmp.mkdir(parents=True, exist_ok=True)
    files = {
        "controller": load_yaml(CONTROLLER_YAML),
        "emulator": load_yaml(EMULATOR_YAML),
        "scenario": base_scenario(),
    }
    out: list[Mutation] = []
    for target, data in files.items():
        for key, value in _leaves(data):
            out.extend(_wrong(target, key, value, tmp))
        out.append(Mutation(target, ("typo_key",), 1, "unknown key"))
    out.append(Mutation("controller", ("watchdog", "timeout_cycle"), 3, "unknown key"))
    out.append(Mutation("emulator", ("bus", "hop_limt"), 0, "unknown key"))
    out.append(Mutation("scenario", ("events", 0, "kloe"), 0.5, "unknown key"))
    return out


def _apply(data: dict[str, Any], m: Mutation) -> dict[str, Any]:
    d = copy.deepcopy(data)
    node: Any = d
    for k in m.key[:-1]:
        node = node[k]
    node[m.key[-1]] = m.value
    return d


def _argv(m: Mutation, i: int, tmp: Path) -> list[str]:
    """The process command for mutation number ``i`` (its files written to ``tmp``)."""
    if m.target == "scenario":
        sc = tmp / f"bad-{i}-scenario.yaml"
        sc.write_text(yaml.safe_dump(_apply(base_scenario(), m), sort_keys=False))
        cfg = write_config(EMULATOR_YAML, tmp / f"bad-{i}-emulator.yaml", {})
        return [PY, "-m", "firmware_sim.cli", "-c", str(cfg), "--scenario", str(sc), "--duration", "0.5"]
    src = CONTROLLER_YAML if m.target == "controller" else EMULATOR_YAML
    good = tmp / f"bad-{i}-{m.target}-base.yaml"
    write_config(src, good, {})  # absolute file paths first, then the wrong value
    cfg = tmp / f"bad-{i}-{m.target}.yaml"
    cfg.write_text(yaml.safe_dump(_apply(load_yaml(good), m), sort_keys=False))
    if m.target == "controller":
        return [PY, "-m", "ehpss_hil.cli", "controller", "-c", str(cfg), "--duration", "0.5"]
    return [PY, "-m", "firmware_sim.cli", "-c", str(cfg), "--duration", "0.5"]


def run_bad_inputs(
    out: Path, muts: list[Mutation] | None = None, parallel: int = 2
) -> tuple[list[BadResult], int]:
    """Run every mutation as a process (``parallel`` at a time) beside a bus logger; returns the
    results and the number of frames the logger saw."""
    out.mkdir(parents=True, exist_ok=True)
    muts = mutations(out) if muts is None else muts
    results: list[BadResult] = []
    with Trial(out) as t:
        logger = t.logger("bus")
        running: list[tuple[Mutation, Child]] = []
        for i, m in enumerate(muts):
            running.append((m, t.spawn(f"bad-{i}", _argv(m, i, out))))
            if len(running) >= parallel:
                results.append(_finish(*running.pop(0)))
        results.extend(_finish(m, c) for m, c in running)
        time.sleep(0.2)
        logger.terminate()
    return results, len(read_candump(out / "bus.log").frames)


def _finish(m: Mutation, c: Child) -> BadResult:
    rc = c.wait(60.0)
    if rc is None:
        c.kill9()
    lines = [ln for ln in c.text().splitlines() if ln.strip()]
    return BadResult(m, rc, lines)
