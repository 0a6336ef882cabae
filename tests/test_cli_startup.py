"""The CLI's start-up: only the command asked for is imported (``ehpss-hil --help`` loads no
command module and no numpy), and every entry of the command table is a real command."""

from __future__ import annotations

import importlib
import subprocess
import sys
from pathlib import Path

import pytest

from ehpss_hil.commands import COMMANDS


@pytest.mark.parametrize("name", sorted(COMMANDS))
def test_command_table_names_real_modules(name: str) -> None:
    mod = importlib.import_module(f"ehpss_hil.commands.{COMMANDS[name][0]}")
    assert mod.NAME == name
    assert callable(mod.run) and callable(mod.add_arguments)


def _loaded_after(code: str) -> set[str]:
    out = subprocess.run(
        [sys.executable, "-c", code + "\nimport sys\nprint(' '.join(sys.modules))"],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
    )
    return set(out.stdout.split())


def test_top_level_help_imports_no_command_and_no_numpy() -> None:
    mods = _loaded_after("from ehpss_hil.cli import build_parser\nbuild_parser().format_help()")
    assert "numpy" not in mods and "scipy" not in mods and "can" not in mods
    assert not any(m.startswith("ehpss_hil.commands.") for m in mods)


def test_the_controller_command_loads_neither_the_simulator_nor_the_emulator() -> None:
    mods = _loaded_after("from ehpss_hil.cli import build_parser\nbuild_parser('controller')")
    assert "ehpss_hil.commands.controller" in mods
    leaked = sorted(m for m in mods if m.startswith(("ehpss_hil.sim", "firmware_sim")))
    assert not leaked, leaked


def test_blas_threads_limited_before_numpy_unless_the_user_chose() -> None:
    code = (
        "import os\nos.environ['OMP_NUM_THREADS'] = '3'\nimport firmware_sim\nimport sys\n"
        "assert 'numpy' not in sys.modules\n"
        "print(os.environ['OPENBLAS_NUM_THREADS'], os.environ['OMP_NUM_THREADS'])"
    )
    env = {k: v for k, v in __import__("os").environ.items() if not k.endswith("_NUM_THREADS")}
    out = subprocess.run(
        [sys.executable, "-c", code], capture_output=True, text=True, check=True, env=env, timeout=120
    )
    assert out.stdout.split() == ["1", "3"]


def test_control_knows_nothing_of_scenarios_configs_frames_or_files() -> None:
    """The control package imports only downwards: no scenario, config, codec, bus, runtime."""
    mods = _loaded_after("import ehpss_hil.control.registry")
    leaked = sorted(
        m
        for m in mods
        if m.startswith(
            (
                "ehpss_hil.scenario",
                "ehpss_hil.config",
                "ehpss_hil.codec",
                "ehpss_hil.bus",
                "ehpss_hil.runtime",
                "ehpss_hil.sim",
                "can",
                "cantools",
            )
        )
    )
    assert not leaked, leaked


def _imported_names() -> dict[str, set[str]]:
    """Each module of ehpss_hil (dotted name; a package by its ``__init__``) and the dotted names
    its import statements name, from the source: every ``import`` and ``from … import`` anywhere
    in the file (function-local and ``TYPE_CHECKING`` ones included), relative ones resolved;
    ``from m import n`` names both ``m`` and ``m.n`` (``n`` may be a submodule)."""
    import ast

    root = Path(__file__).resolve().parent.parent / "ehpss_hil"
    names: dict[str, set[str]] = {}
    for f in root.rglob("*.py"):
        rel = f.relative_to(root.parent).with_suffix("").parts
        mod = ".".join(rel[:-1] if rel[-1] == "__init__" else rel)
        pkg = mod if f.name == "__init__.py" else mod.rsplit(".", 1)[0]
        found = names.setdefault(mod, set())
        for node in ast.walk(ast.parse(f.read_text())):
            if isinstance(node, ast.ImportFrom):
                if node.level:
                    base = pkg.split(".")[: len(pkg.split(".")) - node.level + 1]
                    src = ".".join(base + ([node.module] if node.module else []))
                else:
                    src = node.module or ""
                found |= {src} | {f"{src}.{a.name}" for a in node.names}
            elif isinstance(node, ast.Import):
                found |= {a.name for a in node.names}
    return names


def _import_graph() -> dict[str, set[str]]:
    """Which top-level unit of ehpss_hil (subpackage or module) imports which, from the source."""
    edges: dict[str, set[str]] = {}
    for mod, targets in _imported_names().items():
        unit = mod.split(".")[1] if "." in mod else "ehpss_hil"
        for t in targets:
            if t.startswith("ehpss_hil.") and t.split(".")[1] != unit:
                edges.setdefault(unit, set()).add(t.split(".")[1])
    return edges


def _module_graph() -> dict[str, set[str]]:
    """Which module of ehpss_hil imports which other module of it (names that are no module,
    such as a class imported from one, dropped)."""
    names = _imported_names()
    return {mod: {t for t in targets if t in names and t != mod} for mod, targets in names.items()}


def _cycle(edges: dict[str, set[str]]) -> list[str] | None:
    """One import cycle of ``edges`` as a path ``[a, b, …, a]``, or None (depth-first search)."""
    state: dict[str, int] = {}
    path: list[str] = []

    def visit(u: str) -> list[str] | None:
        state[u] = 1
        path.append(u)
        for v in sorted(edges.get(u, ())):
            if state.get(v) == 1:
                return [*path[path.index(v) :], v]
            if v not in state and (found := visit(v)):
                return found
        state[u] = 2
        path.pop()
        return None

    for u in sorted(edges):
        if u not in state and (found := visit(u)):
            return found
    return None


def test_package_import_graph_has_no_cycles_and_no_library_imports_a_command() -> None:
    edges = _import_graph()
    cycle = _cycle(edges)
    assert cycle is None, f"import cycle: {' -> '.join(cycle)}"
    users = sorted(u for u, vs in edges.items() if "commands" in vs)
    assert users == ["cli"], users


def test_no_module_imports_one_that_imports_it_back() -> None:
    """No import cycle between the modules of ehpss_hil, also not through a function-local or a
    ``TYPE_CHECKING`` import: a module a lower one needs to call back is reached through a
    :class:`typing.Protocol` the lower one defines (as :class:`~ehpss_hil.runtime.periodic.CycleView`)."""
    edges = _module_graph()
    assert len(edges) > 150 and "ehpss_hil.physics.model" in edges["ehpss_hil.physics.hydraulics"]
    cycle = _cycle(edges)
    assert cycle is None, f"import cycle: {' -> '.join(cycle)}"


def test_the_cycle_finder_finds_a_cycle_through_three_modules() -> None:
    edges = {"a": {"b"}, "b": {"c", "d"}, "c": {"a"}, "d": set()}
    assert _cycle(edges) == ["a", "b", "c", "a"]
    assert _cycle({"a": {"b"}, "b": {"d"}, "c": {"b"}}) is None


def test_the_daemon_builds_and_steps_every_mode_without_scipy() -> None:
    """The daemon's imports, and every daemon mode built through the registry as the daemon
    does (its config, ZOH discretisations, gains) and stepped, load no scipy, simulator,
    emulator, report or udp module."""
    code = (
        "from ehpss_hil.daemon import default_factory\n"
        "from ehpss_hil.config import load_controller_config\n"
        "from ehpss_hil.control.base import Measurement\n"
        "from ehpss_hil.control.registry import DAEMON_MODES\n"
        "from ehpss_hil.physics.load import load_params\n"
        "cfg = load_controller_config('configs/controller.yaml')\n"
        "params = load_params(cfg.params)\n"
        "for mode in DAEMON_MODES:\n"
        "    ctrl = default_factory(mode, params, 1.0 / cfg.rate_hz, cfg)\n"
        "    m = Measurement(position_m=1e-4, spool_m=2e-5, reference_m=1e-4, samples=1)\n"
        "    for _ in range(3):\n"
        "        getattr(ctrl, 'observe', lambda m: None)(m)\n"
        "        cmd = ctrl.step(m)\n"
        "    assert abs(cmd.current_a) < 10.0, (mode, cmd)\n"
        "    print('MODE', mode)"
    )
    out = subprocess.run(
        [sys.executable, "-c", code + "\nimport sys\nprint(' '.join(sys.modules))"],
        capture_output=True,
        text=True,
        check=True,
        timeout=120,
        cwd=Path(__file__).resolve().parent.parent,
    )
    lines = out.stdout.splitlines()
    from ehpss_hil.control.registry import DAEMON_MODES

    assert [ln.split()[1] for ln in lines if ln.startswith("MODE ")] == list(DAEMON_MODES)
    mods = set(lines[-1].split())
    leaked = sorted(
        m
        for m in mods
        if m.split(".")[0] == "scipy"
        or m.startswith(("ehpss_hil.sim", "ehpss_hil.report", "ehpss_hil.bus.udp", "firmware_sim"))
    )
    assert not leaked, leaked
