"""Every gate of control/ lives in ControlTuning with its unit and origin, and docs/control.md
lists each one as the tuning has it."""

from __future__ import annotations

import ast
import dataclasses
import importlib
from pathlib import Path
from typing import Any

import pytest

from ehpss_hil import PROJECT_ROOT
from ehpss_hil.config import load_controller_config
from ehpss_hil.control.tuning import ControlTuning, gate_table
from ehpss_hil.errors import ConfigError

CONTROL = PROJECT_ROOT / "ehpss_hil" / "control"
#: module-level numbers that are not gates: the DBC's model slots and fallback reasons (the
#: monitor binds its FallbackReason members once, for its per-sample update) and the protocol's
#: reach
NOT_GATES = {
    "controllers": {"SPOOL_SLOT0", "POSITION_SLOT0", "JOINT_SLOT0", "SMAC_SLOT"},
    "monitor": {"_NONE", "_MISMATCH", "_AT_LIMIT"},
    "sampleclock": {"RESYNC_SAMPLES", "WIRE_COMMANDS"},
}


def _is_number(v: object) -> bool:
    if isinstance(v, bool):
        return False
    if isinstance(v, int | float):
        return True
    return isinstance(v, tuple) and len(v) > 0 and all(_is_number(x) for x in v)


def _module_numbers(source: str, values: dict[str, object]) -> list[str]:
    """Names bound at module level in ``source`` to a number or a tuple of numbers (``values``:
    the module's namespace once run)."""
    names = []
    for node in ast.parse(source).body:
        targets = node.targets if isinstance(node, ast.Assign) else [getattr(node, "target", None)]
        for t in targets:
            if isinstance(t, ast.Name) and _is_number(values.get(t.id)):
                names.append(t.id)
    return names


@pytest.mark.parametrize("path", sorted(CONTROL.rglob("*.py")), ids=lambda p: p.stem)
def test_control_modules_hold_no_numeric_constant_but_slots(path: Path) -> None:
    allowed = NOT_GATES.get(path.stem, set())
    mod = importlib.import_module(".".join(path.relative_to(PROJECT_ROOT).with_suffix("").parts))
    names = _module_numbers(path.read_text(encoding="utf-8"), vars(mod))
    assert [n for n in names if n not in allowed] == []


def test_the_checker_finds_a_module_constant() -> None:
    """The check above is not vacuous: a gate the way control/ used to hold one is found."""
    source = "#: a gate\nHOLD_S = 0.02\nLIMITS = (0.5, 2.0)\nNAME = 'x'\nFLAG = True\nN: int = 3\n"
    values: dict[str, object] = {}
    exec(source, values)
    assert _module_numbers(source, values) == ["HOLD_S", "LIMITS", "N"]


def test_every_tuning_field_has_a_unit_and_an_origin() -> None:
    missing = [
        f.name
        for f in dataclasses.fields(ControlTuning)
        if not f.metadata.get("unit") or not f.metadata.get("origin")
    ]
    assert missing == []


def test_docs_gate_table_lists_every_field_as_the_tuning_has_it() -> None:
    doc = (PROJECT_ROOT / "docs" / "control.md").read_text(encoding="utf-8")
    rows = gate_table()
    assert len(rows) == 2 + len(dataclasses.fields(ControlTuning))
    assert [r for r in rows if r not in doc] == []


def test_a_gate_set_in_the_config_is_loaded_and_an_unknown_key_refused(tmp_path: Path) -> None:
    good = tmp_path / "good.yaml"
    good.write_text("tuning:\n  jump_hold_s: 0.05\n  baseline_limits: [0.6, 1.8]\n")
    cfg = load_controller_config(good)
    assert cfg.tuning.jump_hold_s == 0.05 and cfg.tuning.baseline_limits == (0.6, 1.8)
    for text, key in [
        ("tuning: {jump_hold_ms: 50}", "tuning.jump_hold_ms"),
        ("tuning: {spool_stop_fraction: 1.5}", "tuning.spool_stop_fraction"),
        ("tuning: {creep_samples: 2.5}", "tuning.creep_samples"),
        ("tuning: {baseline_limits: [2.0, 0.5]}", "tuning.baseline_limits"),
    ]:
        bad = tmp_path / "bad.yaml"
        bad.write_text(text + "\n")
        with pytest.raises(ConfigError) as exc:
            load_controller_config(bad)
        assert exc.value.key_path == key


def _fingerprint(obj: object, seen: set[int] | None = None, depth: int = 0) -> list[object]:
    """Every number a configured controller holds (its objects walked through ``__dict__`` and
    ``__slots__``, or mypyc's ``__mypyc_attrs__`` when compiled), the tuning and the params
    themselves left out."""
    seen = set() if seen is None else seen
    if id(obj) in seen or depth > 6:
        return []
    seen.add(id(obj))
    names = list(getattr(obj, "__dict__", {}))
    for klass in type(obj).__mro__:
        # a class compiled by mypyc (ehpss_hil/native.py) lists its attributes in __mypyc_attrs__
        slots = klass.__dict__.get("__slots__", ()) or klass.__dict__.get("__mypyc_attrs__", ())
        names += [slots] if isinstance(slots, str) else list(slots)
    out: list[object] = []
    for name in sorted(set(names)):
        if name in ("tuning", "params") or not hasattr(obj, name):
            continue
        v = getattr(obj, name)
        if callable(v) and not hasattr(v, "__dict__") and not hasattr(v, "__slots__"):
            continue
        if isinstance(v, bool | int | float | str):
            out.append((name, v))
        elif isinstance(v, tuple | list) and all(isinstance(x, int | float) for x in v):
            out.append((name, tuple(v)))
        elif hasattr(v, "__dict__") or hasattr(type(v), "__slots__") or hasattr(type(v), "__mypyc_attrs__"):
            out += _fingerprint(v, seen, depth + 1)
    return out


def _perturbed(name: str, value: object) -> Any:
    if isinstance(value, bool):
        return not value
    if isinstance(value, int):
        return value + 1
    if isinstance(value, float):
        return value * 0.8 if value else 0.01
    assert isinstance(value, tuple)
    return (value[0] * 0.8 if value[0] else 0.01, *value[1:])


@pytest.mark.parametrize("name", [f.name for f in dataclasses.fields(ControlTuning)])
def test_every_gate_is_read_by_a_controller(name: str) -> None:
    """Changing the gate changes what some mode holds once configured: the code reads it from
    the tuning (a copy of the number elsewhere would leave the controllers as they were)."""
    from ehpss_hil.control.registry import MODES, make_controller
    from ehpss_hil.physics.load import load_params

    params = load_params()
    base = ControlTuning()
    other = dataclasses.replace(base, **{name: _perturbed(name, getattr(base, name))})
    assert any(
        _fingerprint(make_controller(m, params, 1e-3, base))
        != _fingerprint(make_controller(m, params, 1e-3, other))
        for m in MODES
    )
