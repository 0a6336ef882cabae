"""``ehpss-hil bench loop``: the real-time loop of both processes on the embedded bus.

Runs ``firmware-sim`` and the controller (mode mmac, fault-free 1 mm sine) as two processes for
``--seconds`` at ``--rate``, as deployed (the emulator's PLANT_TRUTH/PLANT_FAULTS off: a real
valve sends none, and at 2 kHz they were a third of the emulator's frames and of the
controller's receive load), once plainly and once with RT options (SCHED_FIFO, one CPU each),
and prints the controller's cycle compute time (with ``wake_on_sensor``, as in bench runs, the
sensor pair's receive/classify happens while waiting and is not in it; it is in the latency),
wake-up lateness and sensor→command latency (p50/p99/p99.9/max), the overrun ratio, rejected
frames and peak RSS beside docs/design.md §11's targets. Figures come from each process's own
preallocated statistics (``--summary-json``); each variant's first line is its realtime verdict
(:mod:`ehpss_hil.runtime.rtverdict`: did the host hold the rate). Then the host's share
(:mod:`.hostref`): the control step + VALVE_CMD encode alone, after a sleep and back to back.
With ``--fmu`` the emulator's plant is the test FMU (fmpy running our nonlinear plant built by
pythonfmu, :mod:`ehpss_hil.physics.fmutest`; the ``fmu`` extra), and the emulator's overruns are
a target (none) when the run is realtime-valid.
"""

from __future__ import annotations

import argparse
import json
import tempfile
from pathlib import Path
from typing import Any

from ..orchestrate import RunPlan, check_exit_codes, execute
from ..runtime.rtverdict import RealtimeVerdict, end_trip, judge
from . import hostref
from .common import Scorecard, write_json

NAME = "loop"
HELP = "real-time loop of controller + emulator on the embedded bus: latency, jitter, overruns, RSS"

_SCENARIO = """\
name: bench-loop
duration_s: {seconds}
sample_time_s: {ts}
seed: 1
reference: {{kind: sine, amplitude_m: 0.001, omega_rad_s: 5.0}}
noise: {{position_m: 1.0e-6, spool_m: 1.52e-6, pressure_pa: 1.0e4}}
transport_delay_samples: 1
events: []
"""

#: docs/design.md §11: the controller's peak resident size (bytes, 10⁶: "≤ 100 MB"); the
#: emulator is held to it too
RSS_TARGET_BYTES = 100e6

_VARIANTS = {
    "plain": ((), ()),
    "rt": (("--rt-priority", "80", "--cpu", "1"), ("--rt-priority", "79", "--cpu", "0")),
}


def add_arguments(p: argparse.ArgumentParser) -> None:
    p.add_argument("--rate", type=float, default=1000.0, help="loop rate (Hz): 1000 or 2000")
    p.add_argument("--seconds", type=float, default=60.0, help="duration of each variant (s)")
    p.add_argument("--variants", default="plain,rt", help="comma list of: plain, rt")
    p.add_argument("--out", type=Path, default=None, help="keep the run directories here")
    p.add_argument("--json", metavar="FILE", help="write the figures as JSON")
    p.add_argument(
        "--fmu", action="store_true", help="the emulator runs the test FMU as its plant (the fmu extra)"
    )


def _fmu_plant(out: Path) -> str:
    """The scenario's ``plant:`` line for the test FMU, built into ``out``."""
    from ..physics.fmutest import TEST_FMU_MAP, build_test_fmu

    fmu = build_test_fmu(out / "fmu")
    return "plant: " + json.dumps({"model": "fmu", "path": str(fmu), "fmu_map": TEST_FMU_MAP}) + "\n"


def _measure(variant: str, rate: float, seconds: float, out: Path, plant: str = "") -> dict[str, Any]:
    sc = out / "bench-loop.yaml"
    sc.write_text(_SCENARIO.format(seconds=seconds, ts=1.0 / rate) + plant)
    ctrl_args, emu_args = _VARIANTS[variant]
    d = out / variant
    res = execute(
        RunPlan(
            scenario_path=sc,
            mode="mmac",
            out_dir=d,
            bus_logger=False,
            extra_controller_args=ctrl_args,
            extra_emulator_args=emu_args,
            auto_recover=True,
            watchdog_cycles=10,
            truth=False,
        )
    )
    check_exit_codes(res)
    c = json.loads((d / "controller-summary.json").read_text())
    e = json.loads((d / "emulator-summary.json").read_text())
    st = c["stats"]
    verdict = judge(c, e, 1.0 / rate, steal_fraction=res.host_steal_fraction)
    rejected = sum(n for v, n in c["received_by_verdict"].items() if v not in ("OK", "OK_SOME_LOST"))
    return {
        "variant": variant,
        "rate_hz": rate,
        "seconds": seconds,
        "cycles": c["cycles"],
        "compute_s": st["compute_s"],
        "lateness_s": st["lateness_s"],
        "latency_s": st["latency_s"],
        "overruns": st["overruns"],
        "overrun_ratio": st["overruns"] / max(c["cycles"], 1),
        "rejected_frames": rejected,
        "watchdog_trips": c["watchdog_trips"] - end_trip(c),
        **verdict.to_json(),
        "controller_max_rss_bytes": c.get("max_rss_bytes"),
        "emulator_max_rss_bytes": e.get("max_rss_bytes"),
        "woken_by_sensor": c.get("woken_by_sensor", 0),
        "skipped_periods": c.get("skipped_periods", 0),
        "emulator_overruns": e["stats"]["overruns"],
        "emulator_lateness_s": e["stats"]["lateness_s"],
        "host_steal_fraction": res.host_steal_fraction,
        "fmu_plant": bool(plant),
    }


def _us(d: dict[str, float]) -> str:
    return " ".join(f"{d[k] * 1e6:8.1f}" for k in ("p50", "p99", "p99_9", "max"))


def _print_host(ref: dict[str, Any]) -> None:
    a, b = ref["after_sleep_s"], ref["back_to_back_s"]
    print(f"{'host':<7} {'mmac step + encode, slept':<28} {_us(a)}  (no bus, no peer)")
    print(f"{'host':<7} {'mmac step + encode, hot':<28} {_us(b)}  cold/hot p99 {a['p99'] / b['p99']:.1f}×")
    if a["p99"] > 1e-4:
        print(
            f"{'host':<7} this host cannot meet compute p99 ≤ 100 µs with this code: the step and "
            f"encode alone take {a['p99'] * 1e6:.0f} µs at p99 after a sleep "
            "(docs/runtime.md: 'The host's share')"
        )


def _rss_row(variant: str, who: str, peak: int | None, card: Scorecard) -> str:
    """The PASS/FAIL row of one process's peak RSS (its own VmHWM) against :data:`RSS_TARGET_BYTES`."""
    if peak is None:
        return f"{variant:<7} {who} peak RSS: not reported"
    verdict = card.mark(peak <= RSS_TARGET_BYTES, f"{variant} {who} peak RSS {peak / 2**20:.1f} MiB")
    return (
        f"{variant:<7} {who + ' peak RSS':<28} {peak / 2**20:8.1f} MiB = {peak / 1e6:.1f} MB  "
        f"≤ {RSS_TARGET_BYTES / 1e6:.0f} MB {verdict}"
    )


def _print(rows: list[dict[str, Any]], card: Scorecard) -> None:
    print(f"{'variant':<7} {'figure':<28} {'p50 µs':>8} {'p99 µs':>8} {'p99.9 µs':>8} {'max µs':>8}  target")
    for r in rows:
        v = RealtimeVerdict(r["realtime_valid"], r["realtime_reasons"])
        print(f"{r['variant']:<7} {v.line()}")
        ov_target = 1e-4 if r["rate_hz"] <= 1000 else 1e-3
        lines = [
            ("controller compute", r["compute_s"], "p99 ≤ 100 µs", r["compute_s"]["p99"] <= 1e-4),
            (
                "controller wake-up lateness",
                r["lateness_s"],
                "p99 ≤ 150 µs (RT)",
                r["lateness_s"]["p99"] <= 150e-6,
            ),
            ("sensor→command latency", r["latency_s"], "p99 ≤ 300 µs", r["latency_s"]["p99"] <= 300e-6),
            ("emulator wake-up lateness", r["emulator_lateness_s"], "", None),
        ]
        for label, d, target, ok in lines:
            verdict = card.mark(ok, f"{r['variant']} {label} p99 {d['p99'] * 1e6:.0f} µs ({target})")
            print(f"{r['variant']:<7} {label:<28} {_us(d)}  {target} {verdict}")
        ov = r["overrun_ratio"]
        ov_verdict = card.mark(ov <= ov_target, f"{r['variant']} overruns {ov:.2e} (≤ {ov_target:g})")
        print(
            f"{r['variant']:<7} overruns {r['overruns']} / {r['cycles']} cycles = "
            f"{ov:.2e} (target ≤ {ov_target:g}: {ov_verdict}), skipped periods "
            f"{r['skipped_periods']}, cycles started by the sensor pair {r['woken_by_sensor']}; "
            f"emulator overruns "
            f"{r['emulator_overruns']}; rejected frames {r['rejected_frames']}; watchdog trips "
            f"{r['watchdog_trips']} (not counting the one when the emulator ended the run)"
        )
        if r.get("fmu_plant"):
            n = r["emulator_overruns"]
            ok = n == 0 if r["realtime_valid"] else None  # a busy host's overruns are no verdict
            verdict = card.mark(ok, f"{r['variant']} emulator overruns {n} with the FMU plant")
            print(f"{r['variant']:<7} emulator with the FMU plant: {n} overruns (target 0) {verdict}")
        for who in ("controller", "emulator"):
            print(_rss_row(r["variant"], who, r[f"{who}_max_rss_bytes"], card))
        steal = r.get("host_steal_fraction")
        if steal is not None:
            print(
                f"{r['variant']:<7} host steal time during the run: {100 * steal:.1f} % of the "
                "time this VM wanted a CPU (the hypervisor ran another guest)"
            )


def run(args: argparse.Namespace) -> Scorecard:
    rows = []
    with tempfile.TemporaryDirectory(prefix="ehpss-bench-loop-") as tmp:
        out = args.out or Path(tmp)
        out.mkdir(parents=True, exist_ok=True)
        plant = _fmu_plant(out) if args.fmu else ""
        for v in [x.strip() for x in args.variants.split(",") if x.strip()]:
            if v not in _VARIANTS:
                raise SystemExit(f"unknown variant {v!r} (plain, rt)")
            print(f"running {v} at {args.rate:g} Hz for {args.seconds:g} s ...", flush=True)
            rows.append(_measure(v, args.rate, args.seconds, out, plant))
    print("timing the controller's own work on this host (no bus) ...", flush=True)
    host = hostref.measure(args.rate)
    card = Scorecard()
    _print(rows, card)
    _print_host(host)
    write_json(args.json, {"variants": rows, "host": host})
    return card
