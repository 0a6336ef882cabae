"""SIGSTOP of the controller or the emulator process, and what the logs say afterwards (issue
#15). Used by ``tests/test_stall_processes.py``; also runnable by hand (root):

    .venv/bin/python tests/_stall.py --mode mmac --stop controller --seconds 0.5

which prints the figures of one stop with the shipped ``configs/controller.yaml`` (or the test's
bench config with ``--bench``). Nothing here asserts a timing: the figures are read from the two
processes' own candump logs, on the host's wall clock (python-can's receive timestamps and
``time.time()`` at send are both that clock).
"""

from __future__ import annotations

import argparse
import itertools
import json
import math
import os
import signal
import time
from dataclasses import dataclass, field
from pathlib import Path

from _dbc import signal_values
from _proc import EHPSS_HIL, FIRMWARE_SIM, ROOT, Proc

from ehpss_hil.bus.netns import PrivateNetns
from ehpss_hil.canlog import read_log
from ehpss_hil.codec import FrameCodec

EMU_CFG = str(ROOT / "configs" / "emulator.yaml")
#: the bench's watchdog (``ehpss-hil run``: 10 cycles, auto recover) and a reference of 0.2 mm,
#: so that |x_true| ≤ 0.8 mm means |x_true − x_d| ≤ 1 mm whatever x_d is at that moment
BENCH_YAML = """\
bus: {{interface: udp_multicast, channel: 239.74.163.2}}
mode: {mode}
rate_hz: 1000
reference: {{kind: sine, amplitude_m: 0.0002, omega_rad_s: 5.0}}
watchdog: {{timeout_cycles: 10, recovery_cycles: 50, auto_recover: true, failsafe: zero}}
params: {root}/configs/params.yaml
dbc: {root}/dbc/ehpss.dbc
"""
REF_AMPLITUDE_M = 2e-4
REF_OMEGA_RAD_S = 5.0
TS_S = 1e-3  # the loop period of both configs (rate_hz 1000)


@dataclass
class Stop:
    """One SIGSTOP … SIGCONT of ``who`` (wall-clock s)."""

    who: str
    t_stop: float
    t_cont: float


@dataclass
class Pair:
    """Emulator (``--truth``) + controller processes in one private network namespace."""

    tmp: Path
    mode: str
    config: str
    ns: PrivateNetns
    emu: Proc | None = None
    ctl: Proc | None = None
    stops: list[Stop] = field(default_factory=list)

    def start(self) -> None:
        self.emu = Proc(
            self.ns.prefix()
            + FIRMWARE_SIM
            + [
                "-c",
                EMU_CFG,
                "--truth",
                "--log",
                str(self.tmp / "emu.log"),
                "--summary-json",
                str(self.tmp / "emu.json"),
            ]
        )
        assert self.emu.wait_for("realtime on"), self.emu.text
        self.ctl = Proc(
            self.ns.prefix()
            + EHPSS_HIL
            + [
                "controller",
                "-c",
                self.config,
                "--mode",
                self.mode,
                "--log",
                str(self.tmp / "ctl.log"),
                "--summary-json",
                str(self.tmp / "ctl.json"),
            ]
        )
        assert self.ctl.wait_for("first sensor data: ACTIVE"), self.ctl.text + self.emu.text

    def stop(self, who: str, seconds: float) -> None:
        """SIGSTOP ``who`` ("controller"/"emulator") for ``seconds``."""
        p = self.ctl if who == "controller" else self.emu
        assert p is not None
        t0 = time.time()
        os.kill(p.p.pid, signal.SIGSTOP)
        time.sleep(seconds)
        t1 = time.time()
        os.kill(p.p.pid, signal.SIGCONT)
        self.stops.append(Stop(who, t0, t1))

    def recoveries(self) -> int:
        """FAULT → ACTIVE transitions the controller has logged so far."""
        return self.ctl.text.count("ACTIVE again") if self.ctl is not None else 0

    def recovered(self, n: int, limit_s: float = 30.0) -> bool:
        """Wait (at most ``limit_s``) until the controller has logged ``n`` recoveries."""
        assert self.ctl is not None
        end = time.monotonic() + limit_s
        while time.monotonic() < end:
            if self.recoveries() >= n:
                return True
            time.sleep(0.05)
        return False

    def finish(self) -> tuple[dict[str, object], dict[str, object]]:
        """SIGTERM both (controller first); their summaries."""
        for p in (self.ctl, self.emu):
            if p is not None:
                p.terminate()
                assert p.wait() == 0, p.text
        return (
            json.loads((self.tmp / "ctl.json").read_text()),
            json.loads((self.tmp / "emu.json").read_text()),
        )

    def kill(self) -> None:
        for p in (self.ctl, self.emu):
            if p is not None:
                if p.p.poll() is None:
                    os.kill(p.p.pid, signal.SIGCONT)
                p.kill()


@dataclass
class Command:
    """One VALVE_CMD of the controller's log with the SENSOR_POS it echoes (wall-clock s)."""

    n: int  # frame number in the log (file order = the controller's order)
    t: float
    cycle: int
    current_a: float
    enable: bool
    echo_rx_t: float | None  # receive time of the newest SENSOR_POS logged with that counter


@dataclass
class Status:
    n: int
    t: float
    state: str
    reason: str


def controller_log(path: Path) -> tuple[list[Command], list[Status]]:
    """Commands (with the echoed sensor frame's receive time) and CTRL_STATUS frames."""
    from ehpss_hil.protocol.failsafe import FailsafeReason
    from ehpss_hil.runtime.lifecycle import State

    codec = FrameCodec()
    pos, cmd, st = (codec.can_id(n) for n in ("SENSOR_POS", "VALVE_CMD", "CTRL_STATUS"))
    last_rx: dict[int, float] = {}
    cmds: list[Command] = []
    stats: list[Status] = []
    for n, m in enumerate(read_log(path)):
        if m.arbitration_id == pos:
            last_rx[m.data[1] & 0x0F] = m.timestamp
        elif m.arbitration_id == cmd:
            v = signal_values(codec.message("VALVE_CMD"), m.data)
            cmds.append(
                Command(
                    n,
                    m.timestamp,
                    int(v["CycleCount"]),
                    float(v["CurrentSetpoint"]),
                    bool(v["Enable"]),
                    last_rx.get(int(v["SensorCounterEcho"])),
                )
            )
        elif m.arbitration_id == st:
            v = signal_values(codec.message("CTRL_STATUS"), m.data)
            stats.append(
                Status(
                    n, m.timestamp, State(int(v["State"])).name, FailsafeReason(int(v["FailsafeReason"])).name
                )
            )
    return cmds, stats


def truth(path: Path) -> list[tuple[float, float]]:
    """(send time, true piston position m) of every PLANT_TRUTH in the emulator's log."""
    codec = FrameCodec()
    tid = codec.can_id("PLANT_TRUTH")
    msg = codec.message("PLANT_TRUTH")
    return [
        (m.timestamp, signal_values(msg, m.data)["Position"])
        for m in read_log(path)
        if m.arbitration_id == tid
    ]


def resumed_at(cmds: list[Command], s: Stop, ts_s: float = TS_S) -> int:
    """Log frame number from which on the controller's frames come from cycles that started
    after ``s`` ended: for a controller stop, the first VALVE_CMD after it whose CycleCount
    jumped over the stop (by at least half its length in periods of ``ts_s`` s: the loop's grid
    skips the periods it slept through); the cycle in flight when it stopped sends its command
    afterwards (the loop turns it into the fail-safe command when it sees the stall, but a
    process frozen inside its send sends it unchanged), and its own CycleCount may have jumped
    by an overrun before the stop. For an emulator stop, the first VALVE_CMD sent after SIGCONT."""
    after = [i for i, c in enumerate(cmds) if c.t > s.t_cont]
    if not after:
        return 1 << 62
    if s.who == "emulator":
        return cmds[after[0]].n
    over = max(1, round(0.5 * (s.t_cont - s.t_stop) / ts_s))
    for i in after:
        if i > 0 and (cmds[i].cycle - cmds[i - 1].cycle) % 65536 >= over:
            return cmds[i].n
    return cmds[after[0]].n


def x_d(cmds: list[Command], t: float) -> float:
    """The controller's reference at wall-clock time ``t`` (m): the bench config's sine from
    its first ACTIVE cycle (its grid stays on the wall clock, skipped periods included)."""
    t0 = next(c.t for c in cmds if c.enable)
    return REF_AMPLITUDE_M * math.sin(REF_OMEGA_RAD_S * (t - t0))


def figures(pair: Pair, window_s: float) -> list[dict[str, object]]:
    """Per stop: the first statuses after it, the oldest sensor frame a command used after it,
    the largest current step and the largest |x_true| from the stop to the next stop."""
    cmds, stats = controller_log(pair.tmp / "ctl.log")
    xs = truth(pair.tmp / "emu.log")
    out: list[dict[str, object]] = []
    for i, s in enumerate(pair.stops):
        end = pair.stops[i + 1].t_stop if i + 1 < len(pair.stops) else float("inf")
        after = [c for c in cmds if s.t_cont < c.t < end]
        before = [c for c in cmds if c.t < s.t_stop]
        n0 = resumed_at(cmds, s)  # the cycle in flight at the stop sends its command after it
        used = [c for c in after if c.enable and c.n >= n0]
        ages = [c.t - c.echo_rx_t for c in used[:50] if c.echo_rx_t is not None]
        seq = before[-1:] + after
        jumps = [abs(b.current_a - a.current_a) for a, b in itertools.pairwise(seq)]
        xa = [abs(x) for t, x in xs if s.t_stop < t < end]
        dev = [abs(x - x_d(cmds, t)) for t, x in xs if s.t_stop < t < end]
        out.append(
            {
                "stop": f"{s.who} {s.t_cont - s.t_stop:.3f} s",
                "statuses_after": [f"{st.state}/{st.reason}" for st in stats if s.t_cont < st.t < end][:3],
                "in_flight_commands": sum(c.n < n0 for c in after),
                "enabled_commands_after": len(used),
                "stale_rx_used": sum(
                    c.echo_rx_t is not None and c.echo_rx_t < s.t_cont - window_s for c in used
                ),
                "first_50_enabled_age_max_ms": round(1e3 * max(ages), 2) if ages else None,
                "max_current_step_ma": round(1e3 * max(jumps), 3) if jumps else None,
                "max_abs_current_ma_after": round(
                    1e3 * max((abs(c.current_a) for c in after), default=0.0), 3
                ),
                "max_abs_x_true_mm": round(1e3 * max(xa), 4) if xa else None,
                "max_x_true_minus_x_d_mm": round(1e3 * max(dev), 4) if dev else None,  # bench ref
            }
        )
    return out


def main() -> int:
    ap = argparse.ArgumentParser(description=__doc__)
    ap.add_argument("--mode", default="mmac")
    ap.add_argument("--stop", choices=("controller", "emulator"), default="controller")
    ap.add_argument("--seconds", type=float, default=0.5)
    ap.add_argument("--after", type=float, default=1.5, help="run on after the stop (s)")
    ap.add_argument("--bench", action="store_true", help="the tests' bench controller config")
    ap.add_argument("--out", type=Path, default=Path("/tmp/stall"))
    a = ap.parse_args()
    a.out.mkdir(parents=True, exist_ok=True)
    cfg = str(ROOT / "configs" / "controller.yaml")
    window = 3e-3
    if a.bench:
        cfg = str(a.out / "controller.yaml")
        Path(cfg).write_text(BENCH_YAML.format(mode=a.mode, root=ROOT))
        window = 10e-3
    with PrivateNetns() as ns:
        pair = Pair(a.out, a.mode, cfg, ns)
        try:
            pair.start()
            time.sleep(1.0)
            pair.stop(a.stop, a.seconds)
            time.sleep(a.after)
            ctl, _ = pair.finish()
        finally:
            pair.kill()
            if pair.ctl is not None:
                (a.out / "ctl.stderr").write_text(pair.ctl.text)
    for f in figures(pair, window):
        print(json.dumps(f))
    print(
        "controller:",
        {
            k: ctl[k]
            for k in ("state", "failsafe_reason", "watchdog_trips", "skipped_periods", "failsafe_cycles")
        },
    )
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
