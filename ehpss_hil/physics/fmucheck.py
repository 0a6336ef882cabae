"""Checking a user's FMU against ``fmu_map`` before anything runs (``check-config``, and every
program that loads the scenario): it is an FMI 2.0/3.0 co-simulation FMU, it has a binary for
this platform, and each mapped variable exists, is a real number, has the right causality and
declares the SI unit the bench expects (where it declares one). Each failure is one
:class:`~ehpss_hil.errors.ConfigError` naming ``plant.path`` or ``plant.fmu_map.<key>``.

Reads the model description with fmpy (``read_model_description``, ``supported_platforms``);
nothing is extracted or loaded here.
"""

from __future__ import annotations

import zipfile
from dataclasses import dataclass
from pathlib import Path
from typing import Any

from ..errors import ConfigError, one_line
from ..extras import require
from .fmumap import SIGNALS, UNIT_SPELLINGS, FmuMap

#: the FMI major versions the bench runs
FMI_VERSIONS = (2, 3)
#: the variable types the bench exchanges (FMI 2.0 ``Real``, FMI 3.0 ``Float64``)
REAL_TYPES = ("Real", "Float64")


@dataclass(frozen=True)
class FmuDescription:
    """What the plant needs from a checked FMU's model description."""

    #: the FMU's file name (for messages)
    name: str
    fmi_major: int
    #: FMI 2.0 ``guid`` / FMI 3.0 ``instantiationToken``
    guid: str
    model_identifier: str
    #: the FMU's preferred communication step (s): its default experiment's step size or FMI
    #: 3.0's fixed internal step; None when it names none
    step_s: float | None
    #: value reference of each mapped signal (bench key → reference)
    refs: dict[str, int]


def _fail(source: str, key: str, reason: str) -> ConfigError:
    return ConfigError(source, f"plant.{key}", reason)


def _model_description(path: Path, source: str) -> Any:
    """fmpy's model description of ``path``, or ConfigError naming ``plant.path``."""
    from fmpy import read_model_description

    if not path.is_file():
        raise _fail(source, "path", f"no such file: {path}")
    if not zipfile.is_zipfile(path):
        raise _fail(source, "path", f"{path.name} is not an FMU (not a zip archive)")
    try:
        with zipfile.ZipFile(path) as zf:
            if "modelDescription.xml" not in zf.namelist():
                raise _fail(source, "path", f"{path.name} is not an FMU (no modelDescription.xml in the zip)")
        return read_model_description(str(path))
    except ConfigError:
        raise
    except Exception as exc:  # fmpy raises plain Exceptions (XML syntax, schema validation)
        raise _fail(
            source, "path", f"{path.name}: invalid modelDescription.xml: {one_line(str(exc))}"
        ) from exc


def _platform(path: Path, source: str) -> None:
    """ConfigError unless ``path`` has a binary fmpy can load here."""
    import fmpy

    have = [p for p in fmpy.supported_platforms(str(path)) if p != "c-code"]
    if fmpy.platform not in have:
        sources = (
            " (it ships C sources: compile a binary for this platform first)"
            if len(have) < len(fmpy.supported_platforms(str(path)))
            else ""
        )
        raise _fail(
            source,
            "path",
            f"{path.name} has no binary for {fmpy.platform} (it has: {', '.join(have) or 'none'}){sources}",
        )


def _step_s(md: Any) -> float | None:
    """The FMU's preferred communication step (s), if it names one."""
    for value in (
        getattr(md.coSimulation, "fixedInternalStepSize", None),
        getattr(md.defaultExperiment, "stepSize", None) if md.defaultExperiment is not None else None,
    ):
        if value is not None and float(value) > 0.0:
            return float(value)
    return None


def _unit(var: Any) -> str | None:
    """The unit a variable declares (its own, else its declared type's), or None."""
    if var.unit is not None:
        return str(var.unit)
    declared = var.declaredType
    return None if declared is None or declared.unit is None else str(declared.unit)


def _check_variable(var: Any, key: str, fmu: str, source: str) -> None:
    """ConfigError naming ``fmu_map.<key>`` unless ``var`` fits the bench signal ``key``."""
    sig = SIGNALS[key]
    where = f"fmu_map.{key}"
    if var.type not in REAL_TYPES:
        raise _fail(source, where, f"{var.name!r} in {fmu} is {var.type}, expected a real (Real/Float64)")
    if var.shape or var.dimensions:
        raise _fail(source, where, f"{var.name!r} in {fmu} is an array, expected a scalar")
    if sig.direction == "input":
        ok = var.causality == "input" or (var.causality == "parameter" and var.variability == "tunable")
        expected = "input (or a tunable parameter)"
    else:
        ok = var.causality == "output"
        expected = "output"
    if not ok:
        raise _fail(
            source, where, f"{var.name!r} in {fmu} has causality {var.causality}, expected {expected}"
        )
    unit = _unit(var)
    if unit is not None and unit not in UNIT_SPELLINGS[sig.unit]:
        raise _fail(source, where, f"{var.name!r} in {fmu} is in {unit!r}, the bench needs {sig.unit!r} (SI)")


def check_fmu(path: Path, fmap: FmuMap, source: str = "") -> FmuDescription:
    """Check the FMU at ``path`` against ``fmap`` (module docstring); returns what the plant
    needs of it. ConfigError (exit 2) naming the key on any mismatch; MissingExtraError when
    fmpy is not installed."""
    require("fmu", "plant: {model: fmu}", ("fmpy",))
    md = _model_description(path, source)
    name = path.name
    try:
        major = md.fmiMajorVersion
    except (AttributeError, ValueError) as exc:
        raise _fail(source, "path", f"{name}: no valid fmiVersion") from exc
    if major not in FMI_VERSIONS:
        raise _fail(source, "path", f"{name} is an FMI {md.fmiVersion} FMU: the bench runs FMI 2.0 and 3.0")
    if md.coSimulation is None:
        raise _fail(
            source, "path", f"{name} has no co-simulation interface (the bench runs co-simulation FMUs)"
        )
    _platform(path, source)
    variables = {v.name: v for v in md.modelVariables}
    refs: dict[str, int] = {}
    for key, var_name in fmap.mapped().items():
        var = variables.get(var_name)
        if var is None:
            raise _fail(source, f"fmu_map.{key}", f"no variable {var_name!r} in {name}")
        _check_variable(var, key, name, source)
        refs[key] = int(var.valueReference)
    return FmuDescription(
        name=name,
        fmi_major=major,
        guid=str(md.guid),
        model_identifier=str(md.coSimulation.modelIdentifier),
        step_s=_step_s(md),
        refs=refs,
    )
