"""The bench the browser tests of the live monitor share: emulator (truth + FAULT_INJECT
accepted) and an ``mmac`` controller realtime in a private network namespace, ``ehpss-hil
monitor --netns … --allow-inject`` serving its page on the host's 127.0.0.1, headless Chromium
(Debian's ``chromium`` + ``chromium-driver``, driven by selenium), and the waits (generous limits
only; nothing is timed)."""

from __future__ import annotations

import math
import re
import shutil
import tempfile
import time
import warnings
from collections.abc import Callable, Iterator
from contextlib import contextmanager, suppress
from dataclasses import dataclass
from pathlib import Path

import pytest
from _host_share import host_share
from _proc import EHPSS_HIL, EMU_CFG_PATH, FIRMWARE_SIM, ROOT, Proc

from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason

CHROMIUM = shutil.which("chromium") or shutil.which("chromium-browser")
CHROMEDRIVER = shutil.which("chromedriver")
try:
    import selenium  # noqa: F401

    SELENIUM = True
except ImportError:
    SELENIUM = False


def skip_reason() -> str | None:
    if (why := netns_unavailable_reason()) is not None:
        return f"cross-process test: {why}"
    if CHROMIUM is None or CHROMEDRIVER is None:
        return (
            "headless browser test: chromium and chromedriver not installed "
            "(apt-get install chromium chromium-driver)"
        )
    if not SELENIUM:
        return "headless browser test: selenium not installed (pip install -e '.[test]')"
    return None


#: the marks of every test on this bench (started first: they are the longest)
PAGE_MARKS = [
    pytest.mark.netns,
    pytest.mark.slow,
    pytest.mark.skipif(skip_reason() is not None, reason=str(skip_reason())),
]
#: one bench on the host at a time, whatever runs the tests (pytest-xdist workers, two suites):
#: the page's rendering is what the loops compete with, and two Chromiums beside four 1 kHz
#: loops on two cores is a load no bench has. Held exclusively (:func:`_host_share.host_share`
#: on this pair of files, released when its holder exits, however it ends); pytest-xdist's
#: ``xdist_group`` does not group with pytest 9.2 (its node ids no longer take the group suffix
#: xdist 3.8 writes)
BENCH_LOCK = Path(tempfile.gettempdir()) / "ehpss-hil-monitor-bench.lock"
BENCH_GATE = Path(tempfile.gettempdir()) / "ehpss-hil-monitor-bench-gate.lock"
#: how long a bench waits for another to end before it runs anyway, with a warning (s)
BENCH_WAIT_S = 600.0

CTL_YAML = """\
bus: {{interface: udp_multicast, channel: 239.74.163.2}}
mode: mmac
rate_hz: 1000
reference: {{kind: sine, amplitude_m: 0.001, omega_rad_s: 5.0}}
watchdog: {{timeout_cycles: 10, recovery_cycles: 50, auto_recover: true, failsafe: zero}}
params: {root}/configs/params.yaml
dbc: {root}/dbc/ehpss.dbc
"""
#: a generous limit for anything to show on a loaded host (s); not a timing requirement
WAIT_S = 90.0
#: periods a 1 kHz controller overran during one wait beyond which the host is starving it (2 s
#: of its clock lost): adaptation cannot be judged, and waiting on for it is time lost
STARVED_OVERRUNS = 2000
#: fail-safe reasons a starved controller shows
STARVED_FAILSAFES = ("LOOP_OVERRUN", "SENSOR_TIMEOUT", "E2E_ERRORS")


@dataclass
class Monitored:
    """The page's URL, the monitor's process (its output), the controller's and the emulator's
    processes and their logs (candump -L: every frame each sent is in its own), and where the
    monitor writes captures."""

    url: str
    monitor: Proc
    controller: Proc
    emulator: Proc
    log: Path
    emulator_log: Path
    captures: Path


@contextmanager
def monitored_bench(tmp_path: Path) -> Iterator[Monitored]:
    """Emulator + controller in a namespace and the monitor attached (stopped on exit); waits
    for any other bench on the host to end first (:data:`BENCH_LOCK`, at most
    :data:`BENCH_WAIT_S`)."""
    with host_share(True, BENCH_LOCK, BENCH_GATE, BENCH_WAIT_S) as had:
        if not had:
            warnings.warn(f"another monitor bench still ran after {BENCH_WAIT_S:g} s", stacklevel=1)
        with _bench(tmp_path) as m:
            yield m


@contextmanager
def _bench(tmp_path: Path) -> Iterator[Monitored]:
    cfg = tmp_path / "controller.yaml"
    cfg.write_text(CTL_YAML.format(root=ROOT))
    procs: list[Proc] = []
    with PrivateNetns() as ns:
        try:
            emu_log = tmp_path / "emulator.log"
            emu = Proc(
                ns.prefix()
                + FIRMWARE_SIM
                + ["-c", EMU_CFG_PATH, "--truth", "--fault-inject", "--log", str(emu_log)]
            )
            procs.append(emu)
            assert emu.wait_for("realtime on"), emu.text
            netns = f"/proc/{ns.pid}/ns/net"
            # the monitor before the controller: it sees the first ACTIVE cycle, so x_d is aligned
            mon = Proc(
                [
                    *EHPSS_HIL,
                    "monitor",
                    "--netns",
                    netns,
                    "--config",
                    str(cfg),
                    "--port",
                    "0",
                    "--allow-inject",
                    "--capture-dir",
                    str(tmp_path / "captures"),
                ]
            )
            procs.append(mon)
            assert mon.wait_for("monitor: http://"), mon.text
            url = re.search(r"http://[\d.]+:\d+/", mon.text)
            assert url is not None, mon.text
            log = tmp_path / "controller.log"
            ctl = Proc(ns.prefix() + EHPSS_HIL + ["controller", "-c", str(cfg), "--log", str(log)])
            procs.append(ctl)
            assert ctl.wait_for("first sensor data: ACTIVE"), ctl.text + emu.text
            yield Monitored(url.group(0), mon, ctl, emu, log, emu_log, tmp_path / "captures")
        finally:
            for p in reversed(procs):
                p.terminate()
            for p in reversed(procs):
                p.wait()


def browser(downloads: Path | None = None) -> object:
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service

    opts = Options()
    opts.binary_location = str(CHROMIUM)
    if downloads is not None:
        opts.add_experimental_option(
            "prefs", {"download.default_directory": str(downloads), "download.prompt_for_download": False}
        )
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1500,1150"):
        opts.add_argument(a)
    return webdriver.Chrome(service=Service(executable_path=str(CHROMEDRIVER)), options=opts)


def until(what: str, check: Callable[[], bool], give_up: Callable[[], bool] | None = None) -> bool:
    """Poll ``check`` until it holds (True) or :data:`WAIT_S` has passed (AssertionError); a
    ``give_up`` that holds first ends the wait with False."""
    end = time.monotonic() + WAIT_S
    while time.monotonic() < end:
        if check():
            return True
        if give_up is not None and give_up():
            return False
        time.sleep(0.2)
    raise AssertionError(f"the page never showed {what} within {WAIT_S:g} s")


def until_controlling(
    what: str, check: Callable[[], bool], text: Callable[[str], str], overruns0: float
) -> None:
    """Like :func:`until` for what only a controller that keeps time shows (k̂ following a
    fault): when it does not show and the page says the host starved the controller since
    ``overruns0`` (the overrun count shown when the step began: more overruns since, or the
    fail-safe with a starvation or timeout reason), that is what a loaded host does — adaptation
    freezes on late or lost samples and leaving the fail-safe restarts the estimators — and the
    test says so and skips the rest; it does not judge the estimates. The wait ends as soon as
    the controller has overrun :data:`STARVED_OVERRUNS` periods since ``overruns0``."""
    if math.isnan(overruns0):  # not shown yet when the step began
        overruns0 = 0.0
    with suppress(AssertionError):  # not shown in time: starved or a failure, told apart below
        if until(what, check, lambda: number(text("overruns")) - overruns0 > STARVED_OVERRUNS):
            return
    state, reason, overruns = text("state"), text("failsafe-reason"), number(text("overruns"))
    starved = overruns > overruns0 or (state == "FAULT" and reason in STARVED_FAILSAFES)
    if starved:
        pytest.skip(
            f"the host starved the controller ({overruns - overruns0:g} overruns during the wait, "
            f"state {state} {reason}): {what} not judged"
        )
    raise AssertionError(f"the page never showed {what} within {WAIT_S:g} s")


def number(text: str) -> float:
    try:
        return float(text.split()[0])
    except (ValueError, IndexError):
        return float("nan")


def theta(text: str) -> float:
    """θ of a model cell "M2 (θ 0.500)" (NaN when not shown)."""
    m = re.search(r"θ ([-\d.]+)", text)
    return float(m.group(1)) if m else float("nan")
