"""Issue #15 with real processes: SIGSTOP of the controller or of the emulator (``--truth``) for
50 ms, 0.5 s and 5 s, in ``nrc`` and ``mmac``, on ``udp_multicast`` in a private network
namespace, with the bench watchdog (10 cycles, auto recover).

What must hold under any host load (nothing here is a timing target; the waits have generous
limits only so that a broken run fails instead of hanging):
- after each stop the controller is in fail-safe before it controls again, with the right
  reason (controller stopped: LOOP_OVERRUN; emulator stopped: SENSOR_TIMEOUT; on a loaded host
  LOOP_OVERRUN when it also starved the controller, or E2E_ERRORS when the sensor counters
  jumped beyond the E2E window first);
- no enabled VALVE_CMD sent after a stop echoes a sensor frame received before the stop ended
  minus the watchdog window (such a frame is stale at any moment after it);
- the true piston position (PLANT_TRUTH) never gets more than 1 mm from x_d.
"""

from __future__ import annotations

import time
from pathlib import Path

import pytest
from _stall import BENCH_YAML, Pair, controller_log, resumed_at, truth, x_d

from ehpss_hil.bus.netns import PrivateNetns, netns_unavailable_reason

ROOT = Path(__file__).resolve().parent.parent
NETNS_SKIP = netns_unavailable_reason()
netns = pytest.mark.skipif(NETNS_SKIP is not None, reason=f"cross-process test: {NETNS_SKIP}")
WINDOW_S = 10e-3  # the bench watchdog: 10 cycles of 1 ms
LIMIT_S = 60.0  # how long a recovery may take on a loaded host before the test gives up waiting


def _run(tmp: Path, mode: str, stops: list[tuple[str, float]]) -> Pair:
    cfg = tmp / "controller.yaml"
    cfg.write_text(BENCH_YAML.format(mode=mode, root=ROOT))
    with PrivateNetns() as ns:
        pair = Pair(tmp, mode, str(cfg), ns)
        try:
            pair.start()
            time.sleep(0.3)
            for who, seconds in stops:
                n = pair.recoveries()
                pair.stop(who, seconds)
                # the next stop once the controller is ACTIVE again (no figure depends on how
                # long that takes; if a loaded host keeps it in fail-safe, we go on)
                pair.recovered(n + 1, LIMIT_S)
                time.sleep(0.2)
            pair.finish()
        finally:
            pair.kill()
    return pair


def _check(pair: Pair) -> list[str]:
    """The three properties of the module docstring; returns a line per stop (for failures)."""
    cmds, stats = controller_log(pair.tmp / "ctl.log")
    report = []
    for i, s in enumerate(pair.stops):
        end_t = pair.stops[i + 1].t_stop if i + 1 < len(pair.stops) else float("inf")
        n0 = resumed_at(cmds, s)
        before = [st for st in stats if st.t < s.t_stop]
        faulted = before[-1].reason if before and before[-1].state == "FAULT" else None
        # a stopped controller: LOOP_OVERRUN; a stopped emulator: SENSOR_TIMEOUT. On a loaded host
        # another check may trip first: LOOP_OVERRUN (the controller starved too) or E2E_ERRORS (the
        # sensor counters jumped beyond the E2E window: a backlog the socket dropped part of, or the
        # samples the emulator skipped when it caught up)
        allowed = {"LOOP_OVERRUN", "E2E_ERRORS"}
        if s.who == "emulator":
            allowed.add("SENSOR_TIMEOUT")
        if faulted is not None:
            allowed.add(faulted)  # already in fail-safe when it stopped: the reason stays
        # statuses from the stop (emulator) resp. from the first cycle after it (controller)
        lo = s.t_stop if s.who == "emulator" else -1.0
        seq = [st for st in stats if (st.t > lo if s.who == "emulator" else st.n > n0) and st.t < end_t]
        first_active = next((k for k, st in enumerate(seq) if st.state == "ACTIVE" and st.n > n0), len(seq))
        faults = [st for st in seq[:first_active] if st.state == "FAULT"]
        line = (
            f"{s.who} {s.t_cont - s.t_stop:.3f} s: statuses "
            f"{[f'{st.state}/{st.reason}' for st in seq[: first_active + 1]][:4]}"
        )
        report.append(line)
        assert faults, f"no fail-safe before controlling again: {line}"
        assert {st.reason for st in faults} <= allowed, line
        used = [c for c in cmds if c.n >= n0 and c.enable and c.t < end_t]
        stale = [c for c in used if c.echo_rx_t is not None and c.echo_rx_t < s.t_cont - WINDOW_S]
        assert not stale, f"{line}: {len(stale)} commands on stale frames, e.g. {stale[0]}"
    xs = truth(pair.tmp / "emu.log")
    t_active = next(c.t for c in cmds if c.enable)
    dev = max(abs(x - x_d(cmds, t)) for t, x in xs if t > t_active)
    report.append(f"max |x_true - x_d| {dev * 1e3:.3f} mm")
    assert dev <= 1e-3, report
    return report


@netns
@pytest.mark.parametrize("mode", ["nrc", "mmac"])
@pytest.mark.parametrize("who", ["controller", "emulator"])
def test_stop_for_50_ms_then_half_a_second(tmp_path: Path, who: str, mode: str) -> None:
    pair = _run(tmp_path, mode, [(who, 0.05), (who, 0.5)])
    print("\n".join(_check(pair)))


@netns
def test_stop_for_5_s(tmp_path: Path) -> None:
    """Both processes in turn, ``mmac`` (the default mode)."""
    pair = _run(tmp_path, "mmac", [("controller", 5.0), ("emulator", 5.0)])
    print("\n".join(_check(pair)))


@netns
@pytest.mark.parametrize("mode", ["nrc", "mmac"])
def test_a_cpu_hog_beside_the_controller(tmp_path: Path, mode: str) -> None:
    """Three busy processes pinned with the controller on one CPU for 2 s (it gets about a
    quarter of it): whatever the host then does, every fail-safe has a starvation or timeout
    reason, no enabled command uses a stale frame, and the piston never gets more than 1 mm
    from x_d. The counters are printed (overruns, skipped periods, the reasons)."""
    import json
    import os
    import subprocess
    import sys

    cfg = tmp_path / "controller.yaml"
    cfg.write_text(BENCH_YAML.format(mode=mode, root=ROOT))
    hogs: list[subprocess.Popen[bytes]] = []
    with PrivateNetns() as ns:
        pair = Pair(tmp_path, mode, str(cfg), ns)
        try:
            pair.start()
            assert pair.ctl is not None
            cpu = sorted(os.sched_getaffinity(0))[-1]
            os.sched_setaffinity(pair.ctl.p.pid, {cpu})
            time.sleep(0.3)
            for _ in range(3):
                h = subprocess.Popen([sys.executable, "-c", "while True: pass"])
                os.sched_setaffinity(h.pid, {cpu})
                hogs.append(h)
            time.sleep(2.0)
        finally:
            for h in hogs:
                h.kill()
                h.wait()
        try:
            time.sleep(0.5)
            ctl, _ = pair.finish()
        finally:
            pair.kill()
    cmds, stats = controller_log(tmp_path / "ctl.log")
    reasons = {st.reason for st in stats if st.state == "FAULT"}
    assert reasons <= {"LOOP_OVERRUN", "SENSOR_TIMEOUT", "E2E_ERRORS"}, reasons
    xs = truth(tmp_path / "emu.log")
    t_active = next(c.t for c in cmds if c.enable)
    dev = max(abs(x - x_d(cmds, t)) for t, x in xs if t > t_active)
    print(
        json.dumps(
            {
                "mode": mode,
                "max_dev_mm": round(dev * 1e3, 3),
                "fault_reasons": sorted(reasons),
                "skipped_periods": ctl.get("skipped_periods"),
                "watchdog_trips": ctl.get("watchdog_trips"),
                "stale_frames": ctl.get("stale_frames"),
            }
        )
    )
    assert dev <= 1e-3
