"""A second VALVE_CMD transmitter beside a real controller and emulator (issue #16 item 5).

:func:`rogue_trial` runs the controller (x_d = 0: a step of amplitude 0) and the emulator (truth
on) in a private namespace; once the controller is ACTIVE, a rogue process
(``python -m ehpss_hil.reliability.rogue``) sends well-formed VALVE_CMDs — correct E2E, its own
counter and CycleCount, 0.5 A with Enable 1 — at 1 kHz. Expected: the emulator centres the valve
and reports CommandConflict, the controller counts the collision and goes to fail-safe with
reason ID_COLLISION, and the piston (PLANT_TRUTH) never moves more than :data:`MAX_DEVIATION_M`
from x_d. ``python -m ehpss_hil.reliability.rogue --trial DIR`` runs one trial and prints it.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

from ..config import BusConfig
from .procs import PY, Trial, read_json_object

#: the piston's largest deviation from x_d (m) while a rogue commands the valve
MAX_DEVIATION_M = 1e-3
#: what the rogue commands (A) and from which CycleCount it counts (far from the controller's)
ROGUE_CURRENT_A = 0.5
ROGUE_FIRST_CYCLE = 40000


def send_rogue(seconds: float, rate_hz: float, bus_cfg: BusConfig) -> int:
    """Well-formed VALVE_CMDs at ``rate_hz`` for ``seconds`` on an absolute-deadline grid;
    returns the number sent."""
    from ..bus import open_bus
    from ..codec import FrameCodec

    codec = FrameCodec()  # counters of its own
    bus = open_bus(bus_cfg)
    n = 0
    try:
        period = 1.0 / rate_hz
        nxt = time.monotonic()
        end = nxt + seconds
        while nxt < end:
            bus.send(
                codec.encode(
                    "VALVE_CMD",
                    {
                        "CurrentSetpoint": ROGUE_CURRENT_A,
                        "Enable": 1,
                        "CycleCount": (ROGUE_FIRST_CYCLE + n) & 0xFFFF,
                    },
                    timestamp_s=time.time(),
                )
            )
            n += 1
            nxt += period
            time.sleep(max(0.0, nxt - time.monotonic()))
    finally:
        bus.shutdown()
    return n


@dataclass
class RogueResult:
    """What the two processes did about the rogue."""

    sent: int = 0
    controller: dict[str, Any] = field(default_factory=dict)
    emulator: dict[str, Any] = field(default_factory=dict)
    #: the largest |PLANT_TRUTH Position − x_d| over the run (m), and the samples read
    max_deviation_m: float = float("nan")
    truth_samples: int = 0
    command_conflict_seen: bool = False
    exits: dict[str, int | None] = field(default_factory=dict)
    error: str = ""

    @property
    def valve_cmd_collisions(self) -> int:
        return int(self.controller.get("id_collisions", {}).get("VALVE_CMD", 0))

    @property
    def ok(self) -> bool:
        """Emulator centred (a conflict, CommandConflict sent), controller in ID_COLLISION with
        the collision counted, piston within bound, both exits 0."""
        return (
            not self.error
            and self.sent > 0
            and self.emulator.get("command_conflicts", 0) >= 1
            and self.command_conflict_seen
            and self.controller.get("failsafe_reason") == "ID_COLLISION"
            and self.valve_cmd_collisions > 0
            and self.truth_samples > 0
            and self.max_deviation_m <= MAX_DEVIATION_M
            and all(v == 0 for v in self.exits.values())
        )

    def line(self) -> str:
        """One line of figures."""
        c, e = self.controller, self.emulator
        return (
            f"rogue sent {self.sent}; emulator: conflicts {e.get('command_conflicts')}, "
            f"foreign commands {e.get('foreign_commands')}, CommandConflict sent "
            f"{self.command_conflict_seen}; controller: state {c.get('state')} reason "
            f"{c.get('failsafe_reason')}, VALVE_CMD collisions {self.valve_cmd_collisions}; "
            f"piston max |x − x_d| {self.max_deviation_m * 1e6:.1f} µm over "
            f"{self.truth_samples} samples; exits {self.exits}"
            + (f"; error: {self.error}" if self.error else "")
        )


def _truth(log: Path) -> tuple[float, int, bool]:
    """(max |PLANT_TRUTH Position| (m), samples, any SENSOR_AUX with CommandConflict) of the
    emulator's log (x_d is 0 in the trial)."""
    from ..canlog import BadLines, read_log
    from ..codec import FrameCodec

    codec = FrameCodec()
    worst, n, conflict = 0.0, 0, False
    for msg in read_log(log, bad=BadLines()):
        d = codec.classify(msg)
        if d.values is None:
            continue
        if d.name == "PLANT_TRUTH":
            worst = max(worst, abs(float(d.values["Position"])))
            n += 1
        elif d.name == "SENSOR_AUX":
            conflict = conflict or bool(d.values.get("CommandConflict", 0))
    return worst, n, conflict


def rogue_trial(out: Path, rogue_s: float = 1.0, duration_s: float = 3.0) -> RogueResult:
    """Controller + emulator (``duration_s`` of plant time, truth on) and ``rogue_s`` of a
    rogue VALVE_CMD transmitter at 1 kHz once the controller is ACTIVE."""
    res = RogueResult()
    bus = BusConfig()
    with Trial(out) as t:
        # the bench runs' 10-cycle watchdog (a loaded host's stall is no collision); no recovery:
        # the final reason is the one the rogue caused
        ctl = t.controller({"reference": {"kind": "step", "amplitude_m": 0.0}, "watchdog.timeout_cycles": 10})
        emu = t.emulator({}, "--truth", "--duration", repr(duration_s))
        if not ctl.wait_text("first sensor data", 60.0):
            res.error = "controller had no sensor data"
            return res
        rogue = t.spawn(
            "rogue",
            [
                PY,
                "-m",
                "ehpss_hil.reliability.rogue",
                "--seconds",
                repr(rogue_s),
                "--channel",
                bus.channel,
                "--port",
                str(bus.port),
            ],
        )
        rogue.wait(60.0 + rogue_s)
        try:
            res.sent = int(rogue.text().split()[-1])
        except (ValueError, IndexError):
            res.error = f"rogue: {rogue.text()[-200:]}"
        res.exits["emulator"] = emu.wait(60.0 + duration_s)
        res.exits["controller"] = ctl.terminate()
    res.controller = read_json_object(out / "controller.json")
    res.emulator = read_json_object(out / "emulator.json")
    res.max_deviation_m, res.truth_samples, res.command_conflict_seen = _truth(out / "emulator.log")
    return res


def main(argv: list[str] | None = None) -> int:
    """``python -m ehpss_hil.reliability.rogue``: be the rogue (print ``sent N``), or with
    ``--trial DIR`` run one whole trial and print its figures."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--seconds", type=float, default=1.0)
    p.add_argument("--rate", type=float, default=1000.0, help="Hz")
    p.add_argument("--channel", default=BusConfig().channel)
    p.add_argument("--port", type=int, default=BusConfig().port)
    p.add_argument("--trial", type=Path, help="run a whole trial in this directory")
    a = p.parse_args(argv)
    if a.trial is not None:
        res = rogue_trial(a.trial, rogue_s=a.seconds)
        print(res.line())
        print("PASS" if res.ok else "FAIL")
        return 0 if res.ok else 1
    n = send_rogue(a.seconds, a.rate, BusConfig(channel=a.channel, port=a.port))
    print(f"sent {n}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
