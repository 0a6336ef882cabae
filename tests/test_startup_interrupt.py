"""Ctrl-C while a program starts: from the moment ``ehpss_hil`` is imported, SIGINT at any time
gives exit 130 and no traceback (ehpss_hil/interrupt.py), through ``python -m ehpss_hil.cli``
and the ``ehpss-hil`` console script; a library user's ``import ehpss_hil`` keeps Python's
handler.

The signal is sent a delay after a point the test can see: the ``-X importtime`` line of
``ehpss_hil._mf4import``, the module ``ehpss_hil/__init__.py`` imports after installing the
guard. Before that point CPython's own start-up, ``site`` and the console script's lookup run,
which no package can guard (docs/campaigns.md, "Ctrl-C"). No timing asserts: the delays only
spread the signal over the start-up; each outcome must hold whenever the signal lands."""

from __future__ import annotations

import signal
import subprocess
import sys
import threading
import time
from pathlib import Path

import pytest
from _campaign import LIMIT_S, tiny
from _proc import ENV, PY, ROOT

from ehpss_hil import interrupt
from ehpss_hil.interrupt import started_as_program

#: the module whose importtime line is printed once the guard is in place
MARKER = "ehpss_hil._mf4import"
#: delays after the marker (ms): the package's own imports, the command's, its body
DELAYS_MS = (0, 1, 2, 5, 10, 20, 50, 100)
TRIES = 2
CONSOLE_SCRIPT = Path(sys.executable).parent / "ehpss-hil"


def _default_sigint() -> None:
    signal.signal(signal.SIGINT, signal.SIG_DFL)  # as a foreground command (see test_campaign.py)


def _is_marker(line: str) -> bool:
    return line.startswith("import time:") and line.rsplit("|", 1)[-1].strip() == MARKER


def _interrupted(entry: list[str], args: list[str], delay_s: float) -> tuple[int, str]:
    """Start ``entry args`` under ``-X importtime``, SIGINT ``delay_s`` after the marker line;
    the exit code and stderr."""
    proc = subprocess.Popen(
        [PY, "-X", "importtime", *entry, *args],
        cwd=ROOT,
        env=ENV,
        stdout=subprocess.DEVNULL,
        stderr=subprocess.PIPE,
        text=True,
        preexec_fn=_default_sigint,
    )
    lines: list[str] = []
    seen = threading.Event()

    def read() -> None:
        assert proc.stderr is not None
        for line in proc.stderr:
            lines.append(line)
            if _is_marker(line):
                seen.set()
        seen.set()  # EOF: the program ended before the marker (the assert below says so)

    reader = threading.Thread(target=read, daemon=True)
    reader.start()
    try:
        assert seen.wait(LIMIT_S), "no importtime output"
        assert any(_is_marker(ln) for ln in lines), "".join(lines)[-2000:]
        time.sleep(delay_s)
        proc.send_signal(signal.SIGINT)
        rc = proc.wait(timeout=LIMIT_S)
        reader.join(timeout=LIMIT_S)
    finally:
        if proc.poll() is None:
            proc.kill()
            proc.wait()
    return rc, "".join(ln for ln in lines if not ln.startswith("import time:"))


@pytest.mark.parametrize("entry", ["module", "console script"])
def test_ctrl_c_at_any_time_after_the_package_starts_exits_130_without_a_traceback(
    entry: str, tmp_path: Path
) -> None:
    if entry == "console script" and not CONSOLE_SCRIPT.exists():
        pytest.skip(f"no console script {CONSOLE_SCRIPT} (not installed with pip)")
    argv = ["-m", "ehpss_hil.cli"] if entry == "module" else [str(CONSOLE_SCRIPT)]
    f = tiny(tmp_path / "tiny.yaml", samples=40)  # runs for seconds after the last delay
    for n, delay_ms in enumerate(d for d in DELAYS_MS for _ in range(TRIES)):
        out = tmp_path / f"out{n}"
        args = ["campaign", str(f), "--workers", "1", "--out", str(out), "--no-figures"]
        rc, stderr = _interrupted(argv, args, delay_ms / 1000)
        assert rc == 130, (delay_ms, rc, stderr[-2000:])
        assert "Traceback" not in stderr and "KeyboardInterrupt" not in stderr, (delay_ms, stderr[-2000:])


def test_a_library_import_keeps_pythons_handler() -> None:
    """``import ehpss_hil`` in a process that is none of the programs changes nothing; in a
    program, run_console gives the handler back (tests/test_campaign.py: a Ctrl-C mid-campaign
    prints the --resume line, which only the KeyboardInterrupt path does)."""
    code = "import signal, ehpss_hil\nprint(signal.getsignal(signal.SIGINT) is signal.default_int_handler)\n"
    out = subprocess.run(
        [PY, "-c", code],
        cwd=ROOT,
        env=ENV,
        capture_output=True,
        text=True,
        timeout=LIMIT_S,
        check=True,
        preexec_fn=_default_sigint,
    )
    assert out.stdout.split() == ["True"], out.stdout + out.stderr


@pytest.mark.parametrize(
    ("argv", "program"),
    [
        (["python", "-m", "ehpss_hil.cli", "campaign"], True),
        (["python", "-m", "firmware_sim.cli"], True),
        (["python", "-X", "importtime", "/venv/bin/ehpss-hil", "run"], True),
        (["python", "-I", "-W", "ignore", "/venv/bin/firmware-sim"], True),
        (["python", "-Ximporttime", "-m", "ehpss_hil.cli"], True),
        (["python", "-c", "import ehpss_hil", "-m", "ehpss_hil.cli"], False),
        (["python", "-m", "pytest", "-m", "ehpss_hil.cli"], False),
        (["python", "/home/me/ehpss-hil-notes.py"], False),
        (["python", "-m"], False),
        (["python"], False),
    ],
)
def test_a_program_is_told_by_the_interpreters_command_line(argv: list[str], program: bool) -> None:
    assert started_as_program(argv) is program


def test_an_interrupt_landing_in_the_import_system_is_raised_just_after_it() -> None:
    """A KeyboardInterrupt raised inside the import system (a module lock's weakref callback)
    is printed by the interpreter as ignored, with a traceback, and the command went on to its
    end with exit 0 (seen under load in CI). The handler defers it by IMPORT_RETRY_S instead."""
    g: dict[str, object] = {"__name__": "importlib._bootstrap", "sys": sys}
    exec("frame = sys._getframe()", g)
    old = signal.getsignal(signal.SIGALRM)
    try:
        interrupt._raise_interrupt(signal.SIGINT, g["frame"])  # type: ignore[arg-type]
        assert signal.getitimer(signal.ITIMER_REAL)[0] > 0.0  # armed, nothing raised yet
        with pytest.raises(KeyboardInterrupt):
            deadline = time.monotonic() + LIMIT_S
            while time.monotonic() < deadline:
                time.sleep(0.001)
    finally:
        signal.setitimer(signal.ITIMER_REAL, 0.0)
        signal.signal(signal.SIGALRM, old)
        interrupt._STATE["interrupted"] = False
    with pytest.raises(KeyboardInterrupt):  # anywhere else: at once
        interrupt._raise_interrupt(signal.SIGINT, sys._getframe())
    interrupt._STATE["interrupted"] = False
