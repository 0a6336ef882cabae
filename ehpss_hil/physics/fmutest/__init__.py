"""The test FMU: our own nonlinear plant (:mod:`.ehpss_axis`) built into an FMI 2.0 co-simulation
FMU with pythonfmu (the ``fmu`` extra), for the tests, ``bench fmu`` and the worked example of
docs/fmu.md. Built on demand into a folder the caller owns; no FMU binary is committed.

pythonfmu declares no units; :func:`build_test_fmu` adds them to the model description
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
#: the FMI 2.0 base-unit exponents of each unit name used in :data:`UNITS`
_BASE_UNITS: dict[str, dict[str, str]] = {
    "A": {"A": "1"},
    "m": {"m": "1"},
    "Pa": {"kg": "1", "m": "-1", "s": "-2"},
    "1": {},
}
_SCRIPT = Path(__file__).with_name("ehpss_axis.py")


def build_test_fmu(
    dest: Path, *, fail_at_s: float | None = None, units: dict[str, str] | None = None
) -> Path:
    """Build the test FMU into the folder ``dest``; returns the ``.fmu`` path.

    ``fail_at_s``: every ``doStep`` from that time (s) on returns fmi2Error (a hostile FMU; its
    model is written under its own module name, so both variants load in one process).
    ``units``: the unit each variable declares (default :data:`UNITS`; a test gives a wrong one).
    """
    require("fmu", "building the test FMU", ("pythonfmu",))
    from pythonfmu.builder import FmuBuilder

    dest.mkdir(parents=True, exist_ok=True)
    stem = "ehpss_axis" if fail_at_s is None else f"ehpss_axis_fail_{round(fail_at_s * 1e3)}ms"
    with tempfile.TemporaryDirectory(prefix="ehpss-fmu-build-") as tmp:
        script = Path(tmp) / f"{stem}.py"
        text = _SCRIPT.read_text()
        if fail_at_s is not None:
            text = text.replace("FAIL_AT_S: float | None = None", f"FAIL_AT_S: float | None = {fail_at_s!r}")
        script.write_text(text)
        try:
            fmu = FmuBuilder.build_FMU(script, dest=dest / f"{stem}.fmu")
        except Exception as exc:  # pythonfmu reports a failed build with plain exceptions
            raise OutputError(f"cannot build the test FMU into {dest}: {exc}") from exc
        finally:
            while tmp in sys.path:  # the builder puts the script's folder on sys.path
                sys.path.remove(tmp)
    _declare_units(Path(fmu), UNITS if units is None else units)
    return Path(fmu)


def _declare_units(fmu: Path, units: dict[str, str]) -> None:
    """Rewrite ``fmu``'s modelDescription.xml with a ``unit`` on each variable named in
    ``units`` and the matching ``UnitDefinitions`` (placed where the FMI 2.0 schema wants them:
    after the interface type elements)."""
    with zipfile.ZipFile(fmu) as zf:
        entries = {name: zf.read(name) for name in zf.namelist()}
    root = ET.fromstring(entries["modelDescription.xml"])
    defs = ET.Element("UnitDefinitions")
    for name in sorted(set(units.values())):
        unit = ET.SubElement(defs, "Unit", {"name": name})
        ET.SubElement(unit, "BaseUnit", _BASE_UNITS.get(name, {}))
    last_interface = max(i for i, child in enumerate(root) if child.tag in ("ModelExchange", "CoSimulation"))
    root.insert(last_interface + 1, defs)
    for var in root.iter("ScalarVariable"):
        real = var.find("Real")
        if real is not None and var.get("name") in units:
            real.set("unit", units[var.get("name", "")])
    entries["modelDescription.xml"] = ET.tostring(root, encoding="utf-8", xml_declaration=True)
    tmp = fmu.with_suffix(".tmp")
    with zipfile.ZipFile(tmp, "w", zipfile.ZIP_DEFLATED) as zf:
        for name, data in entries.items():
            zf.writestr(name, data)
    shutil.move(tmp, fmu)
