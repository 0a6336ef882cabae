"""``ehpss-hil bench monitor``: the live monitor beside a 1 kHz run — its refresh rate and CPU.

Runs ``ehpss-hil run`` (emulator + controller, mode mmac, fault-free 1 mm sine, PLANT_TRUTH on:
five 1 kHz frame streams, about 4,500 frames/s) with ``--monitor`` on a free port, and while it
runs: a WebSocket client counts the pushes it gets (the page's refresh rate; target ≥ 10 Hz),
headless Chromium (when ``chromium``/``chromedriver`` and selenium are installed) opens the page
and reads the refresh rate the page itself measures, and the monitor process's CPU time
(``/proc/PID/stat``, user + system) is sampled over the same window: its share of one core.
"""

from __future__ import annotations

import argparse
import asyncio
import itertools
import json
import os
import shutil
import socket
import statistics
import tempfile
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

from ..extras import require
from ..orchestrate import RunPlan, check_exit_codes, execute
from .common import Scorecard, write_json

NAME = "monitor"
HELP = "live monitor beside a 1 kHz run: page refresh rate and the monitor's CPU use"

#: the page must refresh at least this often (Hz, issue #20)
REFRESH_TARGET_HZ = 10.0
#: the monitor may use at most this share of one core beside a 1 kHz run (a 2-core bench host
#: also runs the controller and the emulator)
CPU_TARGET = 0.5
_SCENARIO = """\
name: bench-monitor
duration_s: {seconds}
sample_time_s: 0.001
seed: 1
reference: {{kind: sine, amplitude_m: 0.001, omega_rad_s: 5.0}}
noise: {{position_m: 1.0e-6, spool_m: 1.52e-6, pressure_pa: 1.0e4}}
transport_delay_samples: 1
events: []
"""


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument(
        "--seconds", type=float, default=20.0, help="measurement window (s); the run lasts 8 s more"
    )
    p.add_argument("--no-browser", action="store_true", help="skip the headless-Chromium page reading")
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _get_json(url: str) -> Any:
    with urllib.request.urlopen(url, timeout=2.0) as r:
        return json.loads(r.read())


def _wait_for_page(base: str, limit_s: float = 60.0) -> dict[str, Any]:
    end = time.monotonic() + limit_s
    while time.monotonic() < end:
        try:
            cfg: dict[str, Any] = _get_json(base + "api/config")
            if _get_json(base + "api/status")["frames_per_s"] > 0:
                return cfg
        except OSError:
            pass
        time.sleep(0.2)
    raise TimeoutError(f"the monitor at {base} showed no bus traffic within {limit_s:g} s")


def _cpu_s(pid: int) -> float:
    """User + system CPU time of process ``pid`` (s)."""
    fields = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()
    return (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")


async def _count_pushes(url: str, seconds: float) -> list[float]:
    from aiohttp import ClientSession

    times: list[float] = []
    async with ClientSession() as session, session.ws_connect(url) as ws:
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            await ws.receive(timeout=5.0)
            times.append(time.monotonic())
    return times


def _browser_rates(base: str, seconds: float, out: list[float]) -> None:
    from selenium import webdriver
    from selenium.webdriver.chrome.options import Options
    from selenium.webdriver.chrome.service import Service
    from selenium.webdriver.common.by import By

    opts = Options()
    opts.binary_location = str(shutil.which("chromium"))
    for a in ("--headless=new", "--no-sandbox", "--disable-dev-shm-usage", "--window-size=1500,1000"):
        opts.add_argument(a)
    driver = webdriver.Chrome(
        service=Service(executable_path=str(shutil.which("chromedriver"))), options=opts
    )
    try:
        driver.get(base)
        end = time.monotonic() + seconds
        while time.monotonic() < end:
            time.sleep(1.0)
            try:
                out.append(float(driver.find_element(By.ID, "refresh-rate").text))
            except ValueError:
                pass
    finally:
        driver.quit()


def _has_browser() -> bool:
    try:
        import selenium  # noqa: F401
    except ImportError:
        return False
    return shutil.which("chromium") is not None and shutil.which("chromedriver") is not None


def _measure(seconds: float, browser: bool, tmp: Path) -> dict[str, Any]:
    sc = tmp / "bench-monitor.yaml"
    sc.write_text(_SCENARIO.format(seconds=seconds + 8.0))
    port = _free_port()
    plan = RunPlan(
        scenario_path=sc, mode="mmac", out_dir=tmp / "run", bus_logger=False, monitor_port=port, quiet=True
    )
    result: dict[str, Any] = {}
    runner = threading.Thread(target=lambda: result.setdefault("res", execute(plan)), daemon=True)
    runner.start()
    base = f"http://127.0.0.1:{port}/"
    cfg = _wait_for_page(base)
    time.sleep(1.0)  # past the start-up
    page_rates: list[float] = []
    viewer = threading.Thread(target=_browser_rates, args=(base, seconds, page_rates), daemon=True)
    if browser:
        viewer.start()
    cpu0, t0 = _cpu_s(cfg["pid"]), time.monotonic()
    pushes = asyncio.run(_count_pushes(f"ws://127.0.0.1:{port}/ws", seconds))
    cpu1, t1 = _cpu_s(cfg["pid"]), time.monotonic()
    status = _get_json(base + "api/status")
    if browser:
        viewer.join(timeout=seconds + 60.0)
    runner.join(timeout=seconds + 120.0)
    if "res" in result:
        check_exit_codes(result["res"])
    gaps = [b - a for a, b in itertools.pairwise(pushes)]
    return {
        "seconds": t1 - t0,
        "ws_pushes_per_s": (len(pushes) - 1) / (pushes[-1] - pushes[0]) if len(pushes) > 1 else 0.0,
        "ws_gap_max_s": max(gaps) if gaps else None,
        "page_refresh_hz": statistics.median(page_rates) if page_rates else None,
        "page_refresh_min_hz": min(page_rates) if page_rates else None,
        "cpu_share_of_one_core": (cpu1 - cpu0) / (t1 - t0),
        "bus_frames_per_s": status["frames_per_s"],
        "bus_load": status["bus_load"],
        "monitor_rejected_per_s": status["rejected_per_s"],
        "browser": bool(page_rates),
    }


def _print(r: dict[str, Any], card: Scorecard) -> None:
    def verdict(ok: bool, what: str) -> str:
        return card.mark(ok, what)

    print(f"bus: {r['bus_frames_per_s']:.0f} frames/s, load {r['bus_load'] * 100:.1f} % of 1 Mbit/s")
    ws = r["ws_pushes_per_s"]
    ws_verdict = verdict(ws >= REFRESH_TARGET_HZ, f"WebSocket pushes {ws:.1f} Hz")
    print(
        f"WebSocket pushes           {ws:6.1f} Hz (longest gap {r['ws_gap_max_s'] * 1e3:.0f} ms)"
        f"   target ≥ {REFRESH_TARGET_HZ:g} Hz {ws_verdict}"
    )
    if r["page_refresh_hz"] is not None:
        pr = r["page_refresh_hz"]
        pr_verdict = verdict(pr >= REFRESH_TARGET_HZ, f"page refresh {pr:.1f} Hz")
        print(
            f"page refresh (Chromium)    {pr:6.1f} Hz median, {r['page_refresh_min_hz']:.1f} Hz lowest 1-s"
            f" window   target ≥ {REFRESH_TARGET_HZ:g} Hz {pr_verdict}"
        )
    else:
        print("page refresh (Chromium)    not measured (no chromium/chromedriver/selenium, or --no-browser)")
    cpu = r["cpu_share_of_one_core"]
    print(
        f"monitor CPU                {cpu * 100:6.1f} % of one core over {r['seconds']:.1f} s"
        f"   target ≤ {CPU_TARGET * 100:g} % {verdict(cpu <= CPU_TARGET, f'monitor CPU {cpu * 100:.1f} %')}"
    )


def run(args: argparse.Namespace) -> Scorecard:
    require("monitor", "ehpss-hil bench monitor")
    with tempfile.TemporaryDirectory(prefix="ehpss-bench-monitor-") as tmp:
        r = _measure(args.seconds, _has_browser() and not args.no_browser, Path(tmp))
    card = Scorecard()
    _print(r, card)
    write_json(args.json, r)
    return card
