"""The test FMU: our own nonlinear plant (:mod:`.axismodel`) built into an FMI 2.0 co-simulation
FMU with pythonfmu (:mod:`.ehpss_axis`) or into an FMI 3.0 one with pythonfmu3
(:mod:`.ehpss_axis3`) — both in the ``fmu`` extra — for the tests, ``bench fmu`` and the worked
example of docs/fmu.md. Built on demand into a folder the caller owns; no FMU binary is committed.

Neither builder declares units; :func:`build_test_fmu` adds them to the model description
(:data:`UNITS`), so the FMU exercises the bench's unit check as a Simscape or Modelica export does.
"""

from __future__ import annotations

import shutil
import sys
import tempfile
import xml.etree.ElementTree as ET
import zipfile
from pathlib import Path

from ...errors import OutputError
from ...extras import require

#: the FMU's ``fmu_map`` (docs/fmu.md's worked example): the bench's signal → the FMU variable
TEST_FMU_MAP: dict[str, str] = {
    "current_a": "current_a",
    "position_m": "position_m",
    "spool_m": "spool_m",
    "load_pressure_pa": "load_pressure_pa",
    "current_echo_a": "current_echo_a",
    "k_loe": "k_loe",
    "k_q": "k_q",
}
#: the unit each variable declares (FMI 2.0 ``unit`` attribute and ``UnitDefinitions``)
UNITS: dict[str, str] = {
    "current_a": "A",
    "current_echo_a": "A",
    "position_m": "m",
    "spool_m": "m",
    "load_pressure_pa": "Pa",
    "k_loe": "1",
    "k_q": "1",
}
#: the base-unit exponents of each unit name used in :data:`UNITS` (FMI 2.0 and 3.0 ``BaseUnit``)
_BASE_UNITS: dict[str, dict[str, str]] = {
    "A": {"A": "1"},
    "m": {"m": "1"},
    "Pa": {"kg": "1", "m": "-1", "s": "-2"},
    "1": {},
}
#: the model script of each FMI major version, and the extra that builds it
_SCRIPTS: dict[int, tuple[Path, str]] = {
    2: (Path(__file__).with_name("ehpss_axis.py"), "pythonfmu"),
    3: (Path(__file__).with_name("ehpss_axis3.py"), "pythonfmu3"),
}


def build_test_fmu(
    dest: Path,
    *,
    fmi_version: int = 2,
    fail_at_s: float | None = None,
    terminate_at_s: float | None = None,
    units: dict[str, str] | None = None,
    fixed_step_s: float | None = None,
) -> Path:
    """Build the test FMU (FMI ``fmi_version``: 2 or 3) into the folder ``dest``; returns the
    ``.fmu`` path.

    ``fail_at_s``: every step from that time (s) on fails (fmi2Discard / fmi3Discard: a hostile
    FMU). ``terminate_at_s`` (FMI 3.0 only): the step at that time (s) returns OK with
    ``terminateSimulation`` set. A variant's model is written under its own module name, so
    variants load in one process. ``units``: the unit each variable declares (default
    :data:`UNITS`; a test gives a wrong one). ``fixed_step_s`` (FMI 3.0 only): the
    ``fixedInternalStepSize`` the FMU declares (s), written into the file name too.
    """
    script_src, builder = _SCRIPTS[fmi_version]
    require("fmu", "building the test FMU", (builder,))
    if terminate_at_s is not None and fmi_version != 3:
        raise ValueError("terminate_at_s: the terminateSimulation flag is FMI 3.0's")
    if fixed_step_s is not None and fmi_version != 3:
        raise ValueError("fixed_step_s: fixedInternalStepSize is FMI 3.0's")
    dest.mkdir(parents=True, exist_ok=True)
    stem = script_src.stem
    if fail_at_s is not None:
        stem += f"_fail_{round(fail_at_s * 1e3)}ms"
    if terminate_at_s is not None:
        stem += f"_term_{round(terminate_at_s * 1e3)}ms"
    if fixed_step_s is not None:
        stem += f"_fixed_{round(fixed_step_s * 1e6)}us"
    with tempfile.TemporaryDirectory(prefix="ehpss-fmu-build-") as tmp:
        script = Path(tmp) / f"{stem}.py"
        text = script_src.read_text()
        for name, value in (("FAIL_AT_S", fail_at_s), ("TERMINATE_AT_S", terminate_at_s)):
            if value is not None:
                text = text.replace(f"{name}: float | None = None", f"{name}: float | None = {value!r}")
        script.write_text(text)
        try:
            fmu = _build(fmi_version, script, Path(tmp) / "out")
        except Exception as exc:  # the builders report a failed build with plain exceptions
            raise OutputError(f"cannot build the test FMU into {dest}: {exc}") from exc
        finally:
            while tmp in sys.path:  # the builder puts the script's folder on sys.path
                sys.path.remove(tmp)
        out = dest / f"{stem}.fmu"
        shutil.move(fmu, out)
    _declare_units(out, UNITS if units is None else units, fixed_step_s)
    return out


def _build(fmi_version: int, script: Path, out: Path) -> Path:
    """pythonfmu (FMI 2.0) or pythonfmu3 (FMI 3.0) builds ``script`` into the folder ``out``."""
    out.mkdir()
    if fmi_version == 3:
        from pythonfmu3.builder import FmuBuilder as Fmu3Builder

        return Path(Fmu3Builder.build_FMU(script, dest=out))
    from pythonfmu.builder import FmuBuilder

    return Path(FmuBuilder.build_FMU(script, dest=out / f"{script.stem}.fmu"))


def _declare_units(fmu: Path, units: dict[str, str], fixed_step_s: float | None = None) -> None:
    """Rewrite ``fmu``'s modelDescription.xml with a ``unit`` on each variable named in
    ``units`` (FMI 2.0: its ``Real`` element; FMI 3.0: its ``Float64`` element) and the matching
    ``UnitDefinitions`` (placed where both schemas want them: after the interface type
    elements); and FMI 3.0's ``fixedInternalStepSize`` (s) on ``CoSimulation`` when given."""
    with zipfile.ZipFile(fmu) as zf:
        entries = {name: zf.read(name) for name in zf.namelist()}
    root = ET.fromstring(entries["modelDescription.xml"])
    for old in root.findall("UnitDefinitions"):
        root.remove(old)
    defs = ET.Element("UnitDefinitions")
    for name in sorted(set(units.values())):
        unit = ET.SubElement(defs, "Unit", {"name": name})
        ET.SubElement(unit, "BaseUnit", _BASE_UNITS.get(name, {}))
    last_interface = max(i for i, child in enumerate(root) if child.tag in ("ModelExchange", "CoSimulation"))
    root.insert(last_interface + 1, defs)
    cosim = root.find("CoSimulation")
    if fixed_step_s is not None and cosim is not None:
        cosim.set("fixedInternalStepSize", repr(fixed_step_s))
    for var in root.iter("ScalarVariable"):
        real = var.find("Real")
        if real is not None and var.get("name") in units:
            real.set("unit", units[var.get("name", "")])
    for var in root.iter("Float64"):
        if var.get("name") in units:
            var.set("unit", units[var.get("name", "")])
    entries["modelDescription.xml"] = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in entries.items():
            zf.writestr(name, data)
    shutil.move(tmp, fmu)
