"""A scenario back to its file form: the mapping :func:`~ehpss_hil.scenario.load_scenario` reads.

Campaign runs are hashed over this form and the worst cases are written in it, so that
``ehpss-hil sim worst.yaml`` reruns a campaign run exactly (floats written by ``repr``, which
round-trips; a file reference keeps its absolute path).
"""

from __future__ import annotations

import dataclasses
from pathlib import Path
from typing import Any

import yaml

from ..errors import OutputError
from ..scenario import Scenario


def _data(obj: Any) -> Any:
    if dataclasses.is_dataclass(obj) and not isinstance(obj, type):
        out = {}
        for f in dataclasses.fields(obj):
            value = getattr(obj, f.name)
            if f.metadata.get("internal") or value is None:
                continue
            out[f.name] = _data(value)
        return out
    if isinstance(obj, tuple | list):
        return [_data(v) for v in obj]
    return obj


def scenario_data(sc: Scenario) -> dict[str, Any]:
    """``sc`` as the YAML mapping of a scenario file (internal fields and unset values left out;
    the plant section only when it changes the plant, so a run's hash is the same as before
    scenarios had one)."""
    data: dict[str, Any] = _data(sc)
    if sc.plant.is_nominal:
        del data["plant"]
    return data


def write_scenario(sc: Scenario, path: Path) -> Path:
    """Write ``sc`` as a scenario YAML file at ``path``; OutputError when it cannot be written."""
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        path.write_text(yaml.safe_dump(scenario_data(sc), sort_keys=False))
    except OSError as exc:
        raise OutputError(f"cannot write {path}: {exc.strerror or exc}") from exc
    return path
