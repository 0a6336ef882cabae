"""``ehpss-hil bench soak``: controller + emulator at 1 kHz for ``--seconds`` (default 600 s).

Both processes run realtime (mode mmac, fault-free 1 mm sine, the bench watchdog of ``ehpss-hil
run``) in a private network namespace, without candump logs (a 10-minute log would grow by
hundreds of MB). The bench reads each child's ``/proc/PID/status`` and ``/proc/PID/stat`` every
``--interval`` seconds — VmRSS, VmHWM, threads, CPU time, context switches — and prints them at
start (after ``--warmup`` s) and at the end, the RSS growth from start to end (docs/design.md §11: no
growth in a 10-minute soak; controller RSS ≤ 100 MB), the controller's own counter lines (its log
prints one every ``stats_interval_s``) and both processes' final counters (``--summary-json``).
"""

from __future__ import annotations

import argparse
import json
import os
import re
import tempfile
import time
from pathlib import Path
from typing import Any

from ..reliability.procs import READY, Child, Trial, skip_reason
from .common import Scorecard, finite_json, write_json

NAME = "soak"
HELP = "long run of both processes at 1 kHz: RSS and counters at start and end"

_STATUS_KEYS = ("VmRSS", "VmHWM", "Threads", "voluntary_ctxt_switches", "nonvoluntary_ctxt_switches")
_COUNTERS = re.compile(
    r"cycles (\d+), state (\w+), overruns (\d+), rejected frames (\d+), "
    r"fail-safe cycles (\d+)"
)
#: RSS growth from start to end treated as "no growth" (kB): allocator noise, not a leak
GROWTH_LIMIT_KB = 2048
RSS_LIMIT_B = 100e6


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--seconds", type=float, default=600.0, help="soak duration (s)")
    p.add_argument(
        "--warmup",
        type=float,
        default=10.0,
        help="seconds after ACTIVE before the start sample (imports, first GC)",
    )
    p.add_argument("--interval", type=float, default=10.0, help="sampling interval (s)")
    p.add_argument("--out", type=Path, help="keep the run directory here")
    p.add_argument("--json", metavar="FILE", help="write the samples and counters as JSON")


def proc_sample(pid: int) -> dict[str, float]:
    """VmRSS/VmHWM (kB), threads, context switches and CPU seconds of a running process."""
    out: dict[str, float] = {}
    with open(f"/proc/{pid}/status") as f:
        for line in f:
            key, _, rest = line.partition(":")
            if key in _STATUS_KEYS:
                out[key] = float(rest.split()[0])
    with open(f"/proc/{pid}/stat") as f:
        fields = f.read().rsplit(")", 1)[1].split()
    out["cpu_s"] = (int(fields[11]) + int(fields[12])) / os.sysconf("SC_CLK_TCK")
    return out


def _controller_counters(text: str) -> list[dict[str, Any]]:
    return [
        {
            "cycles": int(m[1]),
            "state": m[2],
            "overruns": int(m[3]),
            "rejected": int(m[4]),
            "failsafe_cycles": int(m[5]),
        }
        for m in _COUNTERS.finditer(text)
    ]


def _soak(out: Path, seconds: float, warmup: float, interval: float) -> dict[str, Any]:
    wd = {"watchdog.timeout_cycles": 10, "watchdog.auto_recover": True}
    samples: dict[str, list[dict[str, float]]] = {"controller": [], "emulator": []}
    with Trial(out) as t:
        emu = t.emulator({}, log=False)
        if not emu.wait_text(READY["emulator"]):
            raise RuntimeError(f"emulator did not start: {emu.text()[-500:]}")
        ctl = t.controller(wd, log=False)
        if not ctl.wait_text(READY["controller"]):
            raise RuntimeError(f"controller did not go ACTIVE: {ctl.text()[-500:]}")
        procs: dict[str, Child] = {"controller": ctl, "emulator": emu}
        time.sleep(warmup)
        t0 = time.monotonic()
        while True:
            now = time.monotonic() - t0
            for name, c in procs.items():
                samples[name].append({"t_s": now, **proc_sample(c.pid)})
            if now >= seconds:
                break
            time.sleep(min(interval, seconds - now))
        exits = {name: c.terminate() for name, c in procs.items()}
        text = ctl.text()
    summaries = {
        n: json.loads((out / f"{n}.json").read_text()) for n in procs if (out / f"{n}.json").exists()
    }
    return {
        "seconds": seconds,
        "samples": samples,
        "exits": exits,
        "controller_counters": _controller_counters(text),
        "summaries": summaries,
    }


def _print(r: dict[str, Any], card: Scorecard) -> None:
    print(
        f"{'process':<10} {'when':<6} {'t s':>6} {'VmRSS MiB':>10} {'VmHWM MiB':>10} "
        f"{'threads':>7} {'CPU s':>8} {'vol cs':>9} {'invol cs':>9}"
    )
    for name, ss in r["samples"].items():
        for when, s in (("start", ss[0]), ("end", ss[-1])):
            print(
                f"{name:<10} {when:<6} {s['t_s']:6.0f} {s['VmRSS'] / 1024:10.2f} "
                f"{s['VmHWM'] / 1024:10.2f} {s['Threads']:7.0f} {s['cpu_s']:8.1f} "
                f"{s['voluntary_ctxt_switches']:9.0f} {s['nonvoluntary_ctxt_switches']:9.0f}"
            )
        growth = ss[-1]["VmRSS"] - ss[0]["VmRSS"]
        peak = max(s["VmRSS"] for s in ss)
        ok = growth <= GROWTH_LIMIT_KB and (name != "controller" or peak * 1024 <= RSS_LIMIT_B)
        verdict = card.mark(ok, f"{name} RSS growth {growth / 1024:+.2f} MiB, peak {peak / 1024:.2f} MiB")
        print(
            f"{name:<10} RSS growth start→end {growth / 1024:+.2f} MiB (≤ "
            f"{GROWTH_LIMIT_KB / 1024:g} MiB), peak {peak / 1024:.2f} MiB"
            f"{' (controller ≤ 100 MB)' if name == 'controller' else ''}: "
            f"{verdict}"
        )
    cc = r["controller_counters"]
    for when, c in (("first", cc[0]), ("last", cc[-1])) if cc else ():
        print(f"controller counters ({when} log line): {c}")
    for name, s in r["summaries"].items():
        keys = (
            "cycles",
            "state",
            "watchdog_trips",
            "failsafe_cycles",
            "skipped_periods",
            "periods",
            "command_timeouts",
            "commands_accepted",
            "tx_errors",
            "frames_received",
        )
        figures = {k: s[k] for k in keys if k in s}
        figures["overruns"] = s.get("stats", {}).get("overruns")
        figures["rejected"] = sum(
            n for v, n in s.get("received_by_verdict", {}).items() if v not in ("OK", "OK_SOME_LOST")
        )
        print(f"{name} at the end: {figures}")
    exits = r["exits"]
    print(f"exit codes {exits}: {card.mark(all(v == 0 for v in exits.values()), f'exit codes {exits}')}")


def run(args: argparse.Namespace) -> Scorecard:
    why = skip_reason()
    if why is not None:
        raise SystemExit(f"bench soak: {why}")
    with tempfile.TemporaryDirectory(prefix="ehpss-bench-soak-") as tmp:
        out = args.out or Path(tmp)
        print(f"soak: controller + emulator at 1 kHz for {args.seconds:g} s ...", flush=True)
        r = _soak(out, args.seconds, args.warmup, args.interval)
    card = Scorecard()
    _print(r, card)
    write_json(args.json, finite_json(r))
    return card
