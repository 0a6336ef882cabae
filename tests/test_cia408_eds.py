"""The shipped EDS files load with ``canopen``'s EDS parser and declare what the emulated nodes
serve; a ``cia408:`` section is checked with one-line errors naming its key (exit 2)."""

from __future__ import annotations

import subprocess
from dataclasses import replace
from pathlib import Path
from typing import Any

import pytest
from _proc import FIRMWARE_SIM, ROOT
from canopen.objectdictionary import ODRecord, ODVariable, import_od
from canopen.objectdictionary.datatypes import INTEGER16, INTEGER32, UNSIGNED16

from ehpss_hil.config import Cia408Config, ControllerConfig, EmulatorConfig, load_emulator_config
from ehpss_hil.errors import ConfigError
from ehpss_hil.protocol.cia408.check import check_nodes
from ehpss_hil.protocol.cia408.eds import ENCODER_EDS, VALVE_EDS
from ehpss_hil.scenario import load_scenario
from ehpss_hil.schema import build


def test_valve_eds_loads_with_canopen_and_declares_the_cia408_objects() -> None:
    od: Any = import_od(str(VALVE_EDS), 32)
    assert od[0x1000].default == 0x0000_0198  # device type: CiA 408
    assert od[0x1018][1].default == 0xEE5 and od[0x1018][2].default == 0x408
    assert od[0x1400][1].default == 0x200 + 32  # $NODEID resolved
    assert od[0x1800][1].default == 0x180 + 32 and od[0x1800][2].default == 1  # every SYNC
    assert [od[0x1600][i].default for i in (0, 1, 2)] == [2, 0x6040_0010, 0x6300_0110]
    assert [od[0x1A00][i].default for i in (0, 1, 2)] == [2, 0x6041_0010, 0x6301_0110]
    ctl, status = od[0x6040], od[0x6041]
    assert isinstance(ctl, ODVariable) and ctl.data_type == UNSIGNED16 and ctl.writable and ctl.pdo_mappable
    assert status.data_type == UNSIGNED16 and not status.writable
    sp = od[0x6300]
    assert isinstance(sp, ODRecord)
    assert sp[1].data_type == INTEGER16 and (sp[1].min, sp[1].max) == (-16384, 16384)
    assert od[0x6301][1].data_type == INTEGER16 and not od[0x6301][1].writable
    assert od[0x1016][1].data_type == 0x0007 and od[0x1017].data_type == UNSIGNED16


def test_encoder_eds_loads_with_canopen_and_declares_the_cia406_objects() -> None:
    od: Any = import_od(str(ENCODER_EDS), 33)
    assert od[0x1000].default == 0x0008_0196  # CiA 406, absolute linear encoder
    assert od[0x6004].data_type == INTEGER32 and od[0x6004].pdo_mappable
    assert od[0x1A00][1].default == 0x6004_0020 and od[0x1800][1].default == 0x180 + 33
    assert od[0x6005][1].default == 100  # nm per measuring step
    assert od.device_information.product_name == "EHPSS position encoder (emulated, CiA 406)"


def test_shipped_config_checks_and_loads() -> None:
    cfg = load_emulator_config(ROOT / "configs" / "emulator-cia408.yaml")
    assert cfg.protocol == "cia408" and cfg.nodes.valve_node == 32
    valve, encoder = check_nodes(cfg.nodes, "x")
    assert valve[0x1400][1].default == 0x220 and encoder[0x1800][1].default == 0x1A1


@pytest.mark.parametrize(
    ("change", "key", "text"),
    [
        ({"full_scale_current_a": 0.5}, "cia408.full_scale_current_a", "30.52 µA LSB, coarser than"),
        ({"valve_eds": str(ENCODER_EDS)}, "cia408.valve_eds", "the EDS has no object 0x1400.5"),
        ({"encoder_eds": str(VALVE_EDS)}, "cia408.encoder_eds", "the EDS has no object 0x6004"),
        ({"valve_eds": str(ROOT / "README.md")}, "cia408.valve_eds", "cannot load EDS"),
    ],
)
def test_bad_node_settings_are_one_error_naming_the_key(
    change: dict[str, object], key: str, text: str
) -> None:
    with pytest.raises(ConfigError) as exc:
        check_nodes(replace(Cia408Config(), **change), "emu.yaml")  # type: ignore[arg-type]
    assert exc.value.key_path == key and text in str(exc.value)
    assert "\n" not in str(exc.value)


def test_a_valve_eds_of_another_profile_is_refused(tmp_path: Path) -> None:
    other = tmp_path / "other.eds"
    other.write_text(VALVE_EDS.read_text().replace("DefaultValue=0x00000198", "DefaultValue=0x00000192"))
    with pytest.raises(ConfigError, match="device type 0x00000192 is not CiA 408"):
        check_nodes(replace(Cia408Config(), valve_eds=str(other)), "emu.yaml")


@pytest.mark.parametrize(
    ("data", "key"),
    [
        ({"protocol": "cia408", "cia408": {"valve_node": 5, "encoder_node": 5}}, "cia408.encoder_node"),
        ({"protocol": "cia408", "cia408": {"master_node": 32}}, "cia408.master_node"),
        ({"protocol": "cia408", "cia408": {"valve_node": 128}}, "cia408.valve_node"),
        ({"protocol": "native", "cia408": {}}, "cia408"),
        ({"protocol": "cia408", "mode": "lockstep"}, "mode"),
        ({"protocol": "cia408", "fault_inject": True}, "fault_inject"),
    ],
)
def test_emulator_config_refuses_what_cia408_cannot_do(data: dict[str, object], key: str) -> None:
    with pytest.raises(ConfigError) as exc:
        build(EmulatorConfig, data, "emu.yaml")
    assert exc.value.key_path == key and str(exc.value).startswith(f"emu.yaml: {key}: ")


def test_the_controller_as_cia408_master_refuses_mmac_with_its_flow_gain_test() -> None:
    with pytest.raises(ConfigError, match="the valve reports no load pressure") as exc:
        ControllerConfig(protocol="cia408")
    assert exc.value.key_path == "tuning.flow_gain_test"


def test_firmware_sim_exits_2_with_one_line_for_a_bad_cia408_section(tmp_path: Path) -> None:
    text = (ROOT / "configs" / "emulator-cia408.yaml").read_text()
    bad = tmp_path / "emu.yaml"
    bad.write_text(
        text.replace("params: params.yaml", f"params: {ROOT / 'configs' / 'params.yaml'}")
        .replace("scenario: ../scenarios/fault-free.yaml", "")
        .replace("encoder_node: 33", "encoder_node: 32")
    )
    p = subprocess.run([*FIRMWARE_SIM, "-c", str(bad)], cwd=ROOT, capture_output=True, text=True, timeout=120)
    assert p.returncode == 2, p.stderr
    assert p.stderr.count("\n") == 1 and "cia408.encoder_node: must differ from valve_node (32)" in p.stderr


def test_device_fault_event_is_a_scenario_key(tmp_path: Path) -> None:
    data = {"name": "d", "duration_s": 1.0, "events": [{"t_s": 0.25, "device_fault": 0x5000}]}
    assert load_scenario(tmp_path / "d.yaml", data).device_faults() == [(250, 0x5000)]
    data["events"] = [{"t_s": 0.25, "device_fault": 0x0FFF}]  # not an EMCY error code
    with pytest.raises(ConfigError) as exc:
        load_scenario(tmp_path / "d.yaml", data)
    assert exc.value.key_path == "events[0].device_fault"
