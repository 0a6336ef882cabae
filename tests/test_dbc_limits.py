"""check-config's promise holds for vendor DBCs (issue #29, item 4): a scaling the codec cannot
compute with, a range the controller cannot command, a file over the size cap → one line naming
the key, exit 2, before any bus opens (the controller on a missing interface exits 2, not 3)."""

from __future__ import annotations

import subprocess
from pathlib import Path

import pytest
from _proc import EHPSS_HIL, ENV, FIRMWARE_SIM, ROOT

from ehpss_hil.config import load_controller_config
from ehpss_hil.errors import ConfigError
from ehpss_hil.limits import MAX_DBC_BYTES
from ehpss_hil.physics.load import load_params
from ehpss_hil.protocol import make_codec

VENDOR_DBC = ROOT / "dbc" / "vendor-example.dbc"
CURRENT = 'SG_ CurrentDemand : 23|22@0- (0.0005,0) [-1000|1000] "mA"'
POSITION = 'SG_ PistonPos : 23|22@0- (0.0005,0) [-500|500] "mm"'
SPOOL = 'SG_ SpoolPos : 40|20@1- (0.05,0) [-10000|10000] "um"'
PRESSURE = 'SG_ LoadPress m0 : 16|16@1+ (0.01,-300) [-300|355.35] "bar"'
_SIG = "dbc_map.signals"
#: (row, the good line, its replacement, key named, part of the reason)
BAD_DBCS = [
    ("factor 0", CURRENT, CURRENT.replace("(0.0005,0)", "(0,0)"), "current_setpoint", "factor 0"),
    ("factor 1e-300", POSITION, POSITION.replace("(0.0005,0)", "(1e-300,0)"), "position", "span"),
    ("denormal factor", SPOOL, SPOOL.replace("(0.05,0)", "(1e-310,0)"), "spool", "not denormal"),
    ("offset 1e308", PRESSURE, PRESSURE.replace("(0.01,-300)", "(0.01,1e308)"), "load_pressure", "span"),
    ("min > max", CURRENT, CURRENT.replace("[-1000|1000]", "[1000|-1000]"), "current_setpoint", "min > max"),
    ("[0, 0.001] mA", CURRENT, CURRENT.replace("[-1000|1000]", "[0|0.001]"), "current_setpoint", "span"),
    ("unipolar", CURRENT, CURRENT.replace("[-1000|1000]", "[0|1000]"), "current_setpoint", "spool's stroke"),
]


def _config(tmp: Path, dbc_text: str) -> Path:
    dbc = tmp / "vendor.dbc"
    dbc.write_text(dbc_text)
    cfg = (ROOT / "configs" / "controller-vendor.yaml").read_text()
    cfg = cfg.replace("dbc: ../dbc/vendor-example.dbc", f"dbc: {dbc}")
    cfg = cfg.replace("params: params.yaml", f"params: {ROOT / 'configs' / 'params.yaml'}")
    cfg = cfg.replace("dbc: ../dbc/ehpss.dbc", f"dbc: {ROOT / 'dbc' / 'ehpss.dbc'}")
    p = tmp / "controller.yaml"
    p.write_text(cfg)
    return p


def _cli(argv: list[str]) -> subprocess.CompletedProcess[str]:
    return subprocess.run(argv, cwd=ROOT, env=ENV, capture_output=True, text=True, timeout=300)


@pytest.mark.parametrize(("row", "good", "bad", "key", "reason"), BAD_DBCS, ids=[b[0] for b in BAD_DBCS])
def test_a_bad_scaling_is_one_line_exit_2_before_the_bus(
    tmp_path: Path, row: str, good: str, bad: str, key: str, reason: str
) -> None:
    text = VENDOR_DBC.read_text()
    assert good in text
    cfg = _config(tmp_path, text.replace(good, bad))
    c = load_controller_config(cfg)
    plant = load_params().plant
    with pytest.raises(ConfigError) as exc:
        make_codec(c.protocol, c.dbc, c.ids, str(cfg), c.dbc_map, None, 0.0, plant.stroke_current_a)
    assert exc.value.key_path == f"{_SIG}.{key}" and reason in exc.value.reason, str(exc.value)
    r = _cli([*EHPSS_HIL, "check-config", str(cfg)])
    assert r.returncode == 2 and r.stdout == "" and r.stderr.count("\n") == 1, r.stderr
    assert f"{_SIG}.{key}" in r.stderr
    # the controller on an interface that does not exist: 2 (config) comes before 3 (bus)
    r = _cli([*EHPSS_HIL, "controller", "-c", str(cfg), "--interface", "socketcan", "--channel", "vcan99"])
    assert r.returncode == 2 and f"{_SIG}.{key}" in r.stderr and "Traceback" not in r.stderr, r.stderr


def test_the_emulator_refuses_it_too(tmp_path: Path) -> None:
    cfg = _config(tmp_path, VENDOR_DBC.read_text().replace(CURRENT, CURRENT.replace("(0.0005,0)", "(0,0)")))
    emu = (ROOT / "configs" / "emulator-vendor.yaml").read_text()
    emu = emu.replace("dbc: ../dbc/vendor-example.dbc", f"dbc: {tmp_path / 'vendor.dbc'}")
    emu = emu.replace("params: params.yaml", f"params: {ROOT / 'configs' / 'params.yaml'}")
    emu = emu.replace("dbc: ../dbc/ehpss.dbc", f"dbc: {ROOT / 'dbc' / 'ehpss.dbc'}")
    emu = emu.replace("../scenarios/", f"{ROOT / 'scenarios'}/")
    p = tmp_path / "emulator.yaml"
    p.write_text(emu)
    assert cfg.exists()
    r = _cli([*FIRMWARE_SIM, "-c", str(p), "--interface", "socketcan", "--channel", "vcan99"])
    assert r.returncode == 2 and f"{_SIG}.current_setpoint" in r.stderr and "Traceback" not in r.stderr, (
        r.stderr
    )


def test_a_dbc_over_the_size_cap_is_refused_unread(tmp_path: Path) -> None:
    text = VENDOR_DBC.read_text()
    cfg = _config(tmp_path, text + "\n" * (MAX_DBC_BYTES + 1 - len(text.encode())))
    r = _cli([*EHPSS_HIL, "check-config", str(cfg)])
    assert r.returncode == 2 and r.stderr.count("\n") == 1, r.stderr
    assert "dbc_map.dbc" in r.stderr and f"at most {MAX_DBC_BYTES}" in r.stderr
    cfg = _config(tmp_path, text + "\n" * (MAX_DBC_BYTES - len(text.encode())))  # at the cap: read
    assert _cli([*EHPSS_HIL, "check-config", str(cfg)]).returncode == 0
