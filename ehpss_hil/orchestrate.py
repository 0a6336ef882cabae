"""``ehpss-hil run``: the emulator, the controller and a bus logger as three OS processes.

The run directory gets: the exact configs used (``controller.yaml``, ``emulator.yaml``), the
bus log ``bus.log`` (candump ``-L``, everything on the bus) with its JSON sidecar, each process's
own log, their stdout/stderr, ``run.json`` (commands, exit codes, timings) and ``metrics.json``.

On the embedded ``udp_multicast`` bus the processes run inside a private network namespace when
this process may make one (root + ``unshare``): nothing can leave the host or reach other
processes. Without it they run in the host namespace (TTL 0 keeps frames on the host; a line on
stderr says so), which needs a multicast route; :func:`multicast_route_reason` says what to do
when there is none.

The run directory is prepared by :mod:`ehpss_hil.rundir`: a run only removes files a run wrote,
refuses a non-empty foreign directory unless ``overwrite``, and an unwritable directory is an
:class:`~ehpss_hil.errors.OutputError` (exit 2). A process that ends during start-up gives its
own exit code when it means something (2 bad config or output, 3 missing interface).
"""

from __future__ import annotations

import os
import subprocess
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import yaml

from . import PROJECT_ROOT, __version__
from .bus.netns import PrivateNetns, netns_unavailable_reason
from .canlog.sidecar import write_json_atomic
from .childprocs import last_line, spawn, stop, wait_for_line
from .config import DEFAULT_MULTICAST_GROUP
from .errors import BusUnavailableError, OutputError, ProcessFailedError
from .rundir import prepare_run_dir, record_outputs
from .runtime.hoststeal import cpu_times, steal_fraction
from .scenario import Scenario, load_scenario
from .schema import load_yaml

CONTROLLER_YAML = PROJECT_ROOT / "configs" / "controller.yaml"
EMULATOR_YAML = PROJECT_ROOT / "configs" / "emulator.yaml"
#: lockstep: how long each process waits for the other (s) — the emulator for a VALVE_CMD
#: (``--lockstep-timeout``), the controller for the next sensor frames (``--lockstep-idle``). A
#: loaded host (a TCG VM) can hold one of them back for seconds; the run itself stops the
#: controller once the emulator has finished
LOCKSTEP_PATIENCE_S = 60.0


@dataclass(frozen=True)
class RunPlan:
    """What to run. ``interface``/``channel`` None: the configs' bus."""

    scenario_path: Path
    mode: str = "mmac"
    out_dir: Path = Path("out/run")
    interface: str | None = None
    channel: str | None = None
    lockstep: bool = False
    controller_yaml: Path = CONTROLLER_YAML
    emulator_yaml: Path = EMULATOR_YAML
    extra_controller_args: tuple[str, ...] = ()
    extra_emulator_args: tuple[str, ...] = ()
    #: a third process logging the whole bus to ``bus.log`` (needed for ``metrics.json``)
    bus_logger: bool = True
    quiet: bool = False
    #: bench runs let the controller leave fail-safe after ``watchdog.recovery_cycles`` fresh
    #: cycles (a non-RT host stalls a few ms now and then); False keeps the config's choice
    auto_recover: bool = True
    #: watchdog.timeout_cycles for this run (None: the config's, 3 by default). A non-RT host
    #: stalls a process 3–5 ms now and then; bench runs default to 10 (the emulator's own
    #: command timeout), deployments keep 3 on an RT host.
    watchdog_cycles: int | None = 10
    #: phase lock for this run (µs, ``rt.sensor_age_us``; None: the config's, off by default):
    #: each controller deadline falls this long after the sensor frame arrives, so each cycle
    #: gets exactly one fresh frame despite the host's jitter (docs/runtime.md); at most 0.3 of
    #: the scenario's sample time (at 2 kHz: 150 µs)
    sensor_age_us: float | None = 300.0
    #: ``rt.wake_on_sensor`` for this run (None: the config's): each cycle starts when its
    #: sensor pair arrives, the phase-locked deadline being the latest start
    wake_on_sensor: bool | None = True
    #: the emulator's PLANT_TRUTH/PLANT_FAULTS (needed for metrics.json; a deployment has none:
    #: ``bench loop`` turns them off to load both processes as deployed)
    truth: bool = True
    #: how long the controller may take to appear on the bus (slow VMs need more)
    startup_timeout_s: float = 60.0
    #: how long the emulator may take to finish the scenario (s; None: the duration + 30 s,
    #: lockstep 60 × the duration + 30 s); past it the run is stopped and fails
    finish_timeout_s: float | None = None
    #: a non-empty directory that is no run directory: replace the files a run writes (by
    #: exact name) instead of refusing it
    overwrite: bool = False
    #: serve ``ehpss-hil monitor`` on this port of 127.0.0.1 for the run (None: no monitor); it
    #: listens inside the run's namespace and stops with the run
    monitor_port: int | None = None
    #: the monitor's fault-injection buttons (and the emulator accepting FAULT_INJECT)
    monitor_inject: bool = False


@dataclass
class RunResult:
    """Outcome of one run: exit codes, paths, metrics row (None if no ground truth)."""

    out_dir: Path
    exit_codes: dict[str, int | None] = field(default_factory=dict)
    metrics: dict[str, Any] | None = None
    wall_s: float = 0.0
    #: the emulator had not finished the scenario when the finish timeout stopped it (s)
    unfinished_after_s: float | None = None
    #: the host's steal time over the run (share of the time this VM wanted a CPU; None: not
    #: measured, e.g. no /proc/stat)
    host_steal_fraction: float | None = None


def multicast_route_reason(group: str = DEFAULT_MULTICAST_GROUP) -> str | None:
    """None when this namespace can route the multicast group, else what to do about it."""
    r = subprocess.run(["ip", "route", "get", group], capture_output=True, text=True, check=False)
    if r.returncode == 0:
        return None
    return (
        "no route for multicast on this host: run as root (a private network namespace is "
        "made automatically), or add one with 'ip route add 224.0.0.0/4 dev lo', or use "
        "--interface socketcan --channel vcan0"
    )


def write_config(src: Path, dst: Path, overrides: dict[str, Any]) -> Path:
    """Write ``src`` with ``overrides`` applied and its relative paths made absolute."""
    data = load_yaml(src) or {}
    base = src.resolve().parent
    for key in ("params", "dbc", "scenario"):
        v = data.get(key)
        if isinstance(v, str) and v and not Path(v).is_absolute():
            data[key] = str((base / v).resolve())
    m = data.get("dbc_map")
    if isinstance(m, dict) and isinstance(m.get("dbc"), str) and not Path(m["dbc"]).is_absolute():
        m["dbc"] = str((base / m["dbc"]).resolve())
    for dotted, value in overrides.items():
        node = data
        *parents, leaf = dotted.split(".")
        for p in parents:
            node = node.setdefault(p, {})
        node[leaf] = value
    dst.write_text(yaml.safe_dump(data, sort_keys=False))
    return dst


def _reference_dict(sc: Scenario) -> dict[str, Any]:
    r = sc.reference
    return {
        "kind": r.kind,
        "amplitude_m": r.amplitude_m,
        "omega_rad_s": r.omega_rad_s,
        "start_s": r.start_s,
        "rate_m_s": r.rate_m_s,
        "path": r.path,
    }


def _commands(plan: RunPlan, sc: Scenario, out: Path) -> dict[str, list[str]]:
    py = sys.executable
    bus: dict[str, Any] = {}
    if plan.interface:
        bus["bus.interface"] = plan.interface
    if plan.channel:
        bus["bus.channel"] = plan.channel
    emu_mode = "lockstep" if plan.lockstep else "realtime"
    ctrl_cfg = write_config(
        plan.controller_yaml,
        out / "controller.yaml",
        {
            **bus,
            "mode": plan.mode,
            "reference": _reference_dict(sc),
            **({"watchdog.auto_recover": True} if plan.auto_recover else {}),
            **({"watchdog.timeout_cycles": plan.watchdog_cycles} if plan.watchdog_cycles else {}),
            **(
                {"rt.sensor_age_us": min(plan.sensor_age_us, 0.3e6 * sc.sample_time_s)}
                if plan.sensor_age_us is not None
                else {}
            ),
            **({"rt.wake_on_sensor": plan.wake_on_sensor} if plan.wake_on_sensor is not None else {}),
            "rate_hz": 1.0 / sc.sample_time_s,
        },
    )
    emu_cfg = write_config(
        plan.emulator_yaml,
        out / "emulator.yaml",
        {
            **bus,
            "mode": emu_mode,
            "scenario": str(Path(plan.scenario_path).resolve()),
            "truth": plan.truth,
            **({"fault_inject": True} if plan.monitor_inject else {}),
            "rate_hz": 1.0 / sc.sample_time_s,
        },
    )
    bus_cfg = load_yaml(ctrl_cfg)["bus"]
    return {
        "logger": [
            py,
            "-m",
            "ehpss_hil.cli",
            "log",
            "-i",
            bus_cfg["interface"],
            "-c",
            str(bus_cfg["channel"]),
            "-o",
            str(out / "bus.log"),
        ],
        "controller": [
            py,
            "-m",
            "ehpss_hil.cli",
            "controller",
            "-c",
            str(ctrl_cfg),
            "--log",
            str(out / "controller.log"),
            "--summary-json",
            str(out / "controller-summary.json"),
            *(["--lockstep", "--lockstep-idle", f"{LOCKSTEP_PATIENCE_S:g}"] if plan.lockstep else []),
            *plan.extra_controller_args,
        ],
        "emulator": [
            py,
            "-m",
            "firmware_sim.cli",
            "-c",
            str(emu_cfg),
            "--log",
            str(out / "emulator.log"),
            "--summary-json",
            str(out / "emulator-summary.json"),
            "--duration",
            repr(sc.duration_s),
            *(["--lockstep-timeout", f"{LOCKSTEP_PATIENCE_S:g}"] if plan.lockstep else []),
            *plan.extra_emulator_args,
        ],
    }


def _monitor_command(plan: RunPlan, out: Path, netns: PrivateNetns | None) -> list[str]:
    """``ehpss-hil monitor`` for the run: started outside the namespace (its page on the host's
    127.0.0.1), listening inside it (``--netns``)."""
    return [
        sys.executable,
        "-m",
        "ehpss_hil.cli",
        "monitor",
        "--config",
        str(out / "controller.yaml"),
        "--port",
        str(plan.monitor_port),
        *(["--netns", f"/proc/{netns.pid}/ns/net"] if netns is not None else []),
        *(["--allow-inject"] if plan.monitor_inject else []),
        "--capture-dir",
        str(out / "captures"),
    ]


def _namespace(interface: str, quiet: bool) -> PrivateNetns | None:
    """A private namespace for the embedded bus when one can be made; else None after saying
    so on stderr (BusUnavailableError when the host cannot route the multicast group)."""
    if interface != "udp_multicast":
        return None
    why_not = netns_unavailable_reason()
    if why_not is None:
        return PrivateNetns().start()
    if not quiet:
        print(
            f"ehpss-hil run: no private network namespace ({why_not}): the processes use the "
            "host network (hop limit 0 keeps frames on this host)",
            file=sys.stderr,
            flush=True,
        )
    if (why := multicast_route_reason()) is not None:
        raise BusUnavailableError(why)
    return None


def execute(plan: RunPlan) -> RunResult:
    """Run the three processes for the scenario's duration and collect the results."""
    sc = load_scenario(plan.scenario_path)
    out = plan.out_dir
    prepare_run_dir(out, plan.overwrite)
    try:
        cmds = _commands(plan, sc, out)
    except OSError as exc:
        raise OutputError(f"{out}: cannot write the run's configs: {exc.strerror or exc}") from exc
    interface = load_yaml(out / "controller.yaml")["bus"]["interface"]
    netns = _namespace(interface, plan.quiet)
    prefix = netns.prefix() if netns is not None else []
    res = RunResult(out)
    t0 = time.monotonic()
    ticks0 = cpu_times()
    procs: dict[str, subprocess.Popen[bytes]] = {}
    try:
        if plan.bus_logger:
            procs["logger"] = spawn(cmds["logger"], prefix, out, "logger")
            wait_for_line(out / "logger.out", "logging ", plan.startup_timeout_s, procs)
        if plan.monitor_port is not None:
            cmds["monitor"] = _monitor_command(plan, out, netns)
            procs["monitor"] = spawn(cmds["monitor"], [], out, "monitor")
            wait_for_line(out / "monitor.out", "monitor: http://", plan.startup_timeout_s, procs)
            if not plan.quiet:
                print(last_line(out / "monitor.out"), file=sys.stderr, flush=True)
        procs["controller"] = spawn(cmds["controller"], prefix, out, "controller")
        node = int((load_yaml(out / "controller.yaml").get("ids") or {}).get("controller_node", 1))
        hb = f"{0x700 + node:03X}#"  # the controller's own boot-up heartbeat: it is on the bus
        wait_for_line(out / "controller.log", hb, plan.startup_timeout_s, procs)
        procs["emulator"] = spawn(cmds["emulator"], prefix, out, "emulator")
        limit = plan.finish_timeout_s
        if limit is None:
            limit = sc.duration_s * (60.0 if plan.lockstep else 1.0) + 30.0
        try:
            res.exit_codes["emulator"] = procs["emulator"].wait(timeout=limit)
        except subprocess.TimeoutExpired:
            res.exit_codes["emulator"] = stop(procs["emulator"])
            res.unfinished_after_s = limit
        time.sleep(0.1)
        res.exit_codes["controller"] = stop(procs["controller"])
        if "logger" in procs:
            res.exit_codes["logger"] = stop(procs["logger"])
        if "monitor" in procs:
            res.exit_codes["monitor"] = stop(procs["monitor"])
    finally:
        for p in procs.values():
            stop(p, 2.0)
        if netns is not None:
            netns.close()
    res.wall_s = time.monotonic() - t0
    res.host_steal_fraction = steal_fraction(ticks0, cpu_times())
    _write_run_json(plan, sc, cmds, res, netns is not None)
    return res


def _write_run_json(
    plan: RunPlan, sc: Scenario, cmds: dict[str, list[str]], res: RunResult, private_netns: bool
) -> None:
    meta = {
        "tool": "ehpss-hil run",
        "version": __version__,
        "scenario": sc.name,
        "scenario_path": str(Path(plan.scenario_path).resolve()),
        "mode": plan.mode,
        "lockstep": plan.lockstep,
        "private_netns": private_netns,
        "commands": cmds,
        "exit_codes": res.exit_codes,
        "wall_s": round(res.wall_s, 3),
        "host_steal_fraction": res.host_steal_fraction,
        "started_unix_s": time.time() - res.wall_s,
        "pid": os.getpid(),
    }
    try:
        write_json_atomic(plan.out_dir / "run.json", meta)
    except OSError as exc:
        raise OutputError(f"{plan.out_dir / 'run.json'}: cannot write: {exc.strerror or exc}") from exc
    record_outputs(plan.out_dir)


def check_exit_codes(res: RunResult) -> None:
    """Raise when a process did not end cleanly (exit 0): :class:`ProcessFailedError` with the
    processes' exit code when they all share one (3: a missing interface); also when the
    emulator had not finished the scenario by the finish timeout (its log is then short)."""
    if res.unfinished_after_s is not None:
        raise ProcessFailedError(
            f"the emulator had not finished the scenario after {res.unfinished_after_s:g} s and was "
            f"stopped: the logs in {res.out_dir} end early"
        )
    bad = {k: v for k, v in res.exit_codes.items() if v != 0}
    if bad:
        tails = []
        for name in bad:
            f = res.out_dir / f"{name}.out"
            if f.exists():
                tails.append(
                    f"--- {name}.out ---\n" + "\n".join(f.read_text(errors="replace").splitlines()[-8:])
                )
        codes = set(bad.values())
        raise ProcessFailedError(
            f"processes ended badly: {bad}\n" + "\n".join(tails), codes.pop() if len(codes) == 1 else None
        )
