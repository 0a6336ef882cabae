"""The native build (ehpss_hil/native.py): a stale build is never imported, and the compiled
controller computes exactly what its source computes.

Each case runs a fresh interpreter on a copy of the package (with this checkout's build
products, when ``make`` built them): the guard acts at import, once per process.
"""

from __future__ import annotations

import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from ehpss_hil import PROJECT_ROOT, native

_PROBE = """
import json, sys
import ehpss_hil.control.bank as bank
import ehpss_hil.physics.hydraulics as hyd
from ehpss_hil import native
print(json.dumps({"bank": bank.__file__, "hyd": hyd.__file__, "compiled": native.compiled()}))
"""

_TRACE = """
import sys
import numpy as np
from ehpss_hil.physics.load import load_params
from ehpss_hil.scenario import load_scenario
from ehpss_hil.sim.lockstep import run_scenario
r = run_scenario(load_scenario(sys.argv[1]), "mmac", load_params())
np.save(sys.argv[2], np.stack([r.x_true_m, r.current_a, r.k_loe_hat, r.k_dft_hat]))
"""

#: a nonlinear-plant run with faults: the controller's every branch family and the compiled plant
SCENARIO = PROJECT_ROOT / "scenarios" / "mismatch" / "nl-kc080-bias.yaml"


def _copy(tmp_path: Path) -> Path:
    """The package, with whatever build products this checkout has, under ``tmp_path``."""
    dst = tmp_path / "tree"
    shutil.copytree(
        PROJECT_ROOT / "ehpss_hil", dst / "ehpss_hil", ignore=shutil.ignore_patterns("__pycache__")
    )
    return dst


def _run(tree: Path, code: str, *args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(tree)}
    return subprocess.run(
        [sys.executable, "-c", code, *args], cwd=tree, env=env, capture_output=True, text=True, timeout=300
    )


def test_every_compiled_module_is_listed_once_with_its_source() -> None:
    mods = native.modules()
    assert len(mods) == len(set(mods))
    assert "ehpss_hil.control.adaptive" in mods and "ehpss_hil.physics.hydraulics" in mods
    assert all(native.source(m).is_file() and native.source(m).name != "__init__.py" for m in mods)


def test_an_edited_source_is_imported_from_source_with_one_line_on_stderr(tmp_path: Path) -> None:
    if not native.compiled():
        pytest.skip(f"no native build in this checkout ({native.status()})")
    tree = _copy(tmp_path)
    fresh = _run(tree, _PROBE)
    assert fresh.returncode == 0, fresh.stderr
    got = json.loads(fresh.stdout)
    assert got["bank"].startswith(str(tree)) and got["bank"].endswith(".so")
    assert got["hyd"].endswith(".so") and got["compiled"]
    assert fresh.stderr == ""
    # a comment appended to one compiled module: every compiled module comes from source
    src = tree / "ehpss_hil" / "control" / "estimates.py"
    src.write_text(src.read_text(encoding="utf-8") + "# edited\n", encoding="utf-8")
    edited = _run(tree, _PROBE)
    assert edited.returncode == 0, edited.stderr
    got = json.loads(edited.stdout)
    assert got["bank"].endswith("bank.py") and got["hyd"].endswith("hydraulics.py")
    assert not got["compiled"]
    lines = edited.stderr.splitlines()
    assert len(lines) == 1 and "ehpss_hil.control.estimates" in lines[0] and "make native" in lines[0]


def test_an_extension_the_build_did_not_make_is_not_imported(tmp_path: Path) -> None:
    """A module that left the build keeps its old extension on disk (its shim points into a
    shared library that no longer holds it: imported, an AttributeError)."""
    if not native.compiled():
        pytest.skip(f"no native build in this checkout ({native.status()})")
    tree = _copy(tmp_path)
    bank = native.extension("ehpss_hil.control.bank")
    assert bank is not None
    left = tree / "ehpss_hil" / "sim" / bank.name.replace("bank", "lockstep", 1)
    shutil.copy2(tree / "ehpss_hil" / "control" / bank.name, left)
    out = _run(tree, _PROBE + "import ehpss_hil.sim.lockstep as ls; print(ls.__file__)\n")
    assert out.returncode == 0, out.stderr
    assert out.stdout.splitlines()[-1].endswith("lockstep.py")
    lines = out.stderr.splitlines()
    assert len(lines) == 1 and "ehpss_hil.sim.lockstep" in lines[0]


def test_extensions_without_a_manifest_are_not_imported(tmp_path: Path) -> None:
    if not native.compiled():
        pytest.skip(f"no native build in this checkout ({native.status()})")
    tree = _copy(tmp_path)
    (tree / "ehpss_hil" / "_native.json").unlink()
    out = _run(tree, _PROBE)
    assert out.returncode == 0, out.stderr
    got = json.loads(out.stdout)
    assert got["bank"].endswith("bank.py") and not got["compiled"]


def test_the_compiled_controller_and_plant_compute_what_their_source_computes(tmp_path: Path) -> None:
    if not native.compiled():
        pytest.skip(f"no native build in this checkout ({native.status()})")
    tree = _copy(tmp_path)
    compiled = _run(tree, _TRACE, str(SCENARIO), str(tmp_path / "compiled.npy"))
    assert compiled.returncode == 0, compiled.stderr
    shutil.rmtree(tree)
    tree = _copy(tmp_path)
    (tree / "ehpss_hil" / "_native.json").unlink()  # the extensions stay, unused
    source = _run(tree, _TRACE, str(SCENARIO), str(tmp_path / "source.npy"))
    assert source.returncode == 0, source.stderr
    a, b = np.load(tmp_path / "compiled.npy"), np.load(tmp_path / "source.npy")
    assert a.shape == b.shape and a.shape[1] > 1000
    assert np.array_equal(a, b, equal_nan=True)
    assert np.ptp(a[3]) > 0.05  # the run moved the estimates: the comparison saw the branches
