"""``ehpss-hil run --monitor PORT``: the monitor starts on the host's 127.0.0.1, listens inside
the run's private namespace, hears the run's frames, takes an injection that the emulator applies
(PLANT_FAULTS, in the run's own bus log), and stops with the run (exit 0). Nothing is timed."""

from __future__ import annotations

import json
import socket
import threading
import time
import urllib.request
from pathlib import Path
from typing import Any

import numpy as np
import pytest
from _proc import STARTUP_LIMIT_S
from _scenarios import short_scenario_yaml

from ehpss_hil.bus.netns import netns_unavailable_reason
from ehpss_hil.orchestrate import RunPlan, check_exit_codes, execute
from ehpss_hil.report.logdata import load_log_run

NETNS_SKIP = netns_unavailable_reason()
pytestmark = [
    pytest.mark.netns,
    pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}"),
]


def _free_port() -> int:
    with socket.socket() as s:
        s.bind(("127.0.0.1", 0))
        return int(s.getsockname()[1])


def _post(url: str, body: dict[str, Any]) -> dict[str, Any]:
    """POST as a script does: the injection token read from the page's /api/config."""
    with urllib.request.urlopen(url.rsplit("/api/", 1)[0] + "/api/config", timeout=5.0) as r:
        token = json.loads(r.read())["token"]
    req = urllib.request.Request(
        url,
        data=json.dumps(body).encode(),
        headers={"Content-Type": "application/json", "X-Monitor-Token": token},
    )
    with urllib.request.urlopen(req, timeout=5.0) as r:
        return dict(json.loads(r.read()))


def test_run_with_monitor(tmp_path: Path) -> None:
    sc = tmp_path / "monitored.yaml"
    sc.write_text(short_scenario_yaml("monitored", 6.0, "{t_s: 5.9, k_q: 1.0}"))
    port = _free_port()
    base = f"http://127.0.0.1:{port}/"
    seen: dict[str, Any] = {"frames": 0}

    def watch() -> None:
        end = time.monotonic() + 120.0
        while time.monotonic() < end and "sent" not in seen:
            try:
                with urllib.request.urlopen(base + "api/status", timeout=2.0) as r:
                    st = json.loads(r.read())
                seen["frames"] = st["frames"]
                # once the controller has been ACTIVE (the emulator's scenario, which sets the
                # faults, starts then); a loaded host may hold it in its fail-safe afterwards,
                # and the emulator applies the injection in either state
                if st.get("state") in ("ACTIVE", "FAULT") and st["frames"] > 1000:
                    seen["sent"] = _post(base + "api/inject", {"kind": "k_loe", "value": 0.6})
            except OSError:
                pass
            time.sleep(0.1)

    watcher = threading.Thread(target=watch, daemon=True)
    watcher.start()
    out = tmp_path / "run"
    res = execute(
        RunPlan(
            scenario_path=sc,
            out_dir=out,
            monitor_port=port,
            monitor_inject=True,
            quiet=True,
            startup_timeout_s=STARTUP_LIMIT_S,
        )
    )
    watcher.join(timeout=10.0)
    check_exit_codes(res)
    assert res.exit_codes["monitor"] == 0
    assert f"monitor: {base}" in (out / "monitor.out").read_text()
    cmd = json.loads((out / "run.json").read_text())["commands"]["monitor"]
    assert "--netns" in cmd and "--allow-inject" in cmd
    assert seen["frames"] > 1000, seen
    assert (seen.get("sent") or {}).get("sent") == "FAULT_INJECT k_loe = 0.6", seen
    # the emulator applied it: its true k_LOE, as logged on the run's bus, went to 0.6 (the
    # scenario has no LOE event, so 0.6 can only come from the page; which rows before the
    # injection carry truth depends on when a loaded host let the loop reach ACTIVE)
    k = load_log_run(out / "bus.log").result.true_k_loe
    k = k[np.isfinite(k)]
    assert k[-1] == pytest.approx(0.6, abs=1e-4)
    assert set(np.round(k, 4)) <= {1.0, 0.6}
