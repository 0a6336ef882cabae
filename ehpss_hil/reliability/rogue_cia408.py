"""A rogue CANopen node beside the CiA 408 master and the emulated valve (issue #29 item 1).

:func:`rogue_cia408_trial` runs ``ehpss-hil controller`` with ``configs/controller-cia408.yaml``
(x_d = 0: a step of amplitude 0) and ``firmware-sim`` with ``configs/emulator-cia408.yaml``
(``--truth``: PLANT_TRUTH beside the CANopen frames) in a private namespace; once the controller
is ACTIVE, a rogue process (``python -m ehpss_hil.reliability.rogue_cia408 --case CASE``) sends
one of :data:`CASES` on the embedded bus. Judged: the controller's fail-safe reason, the
controller cycles (its RPDOs) from the rogue's first frame to its first RPDO asking for
DISABLED, and the piston's largest deviation from x_d (PLANT_TRUTH; where the emulator sends
none, an older build, the encoder's position value stands in). A trial in which the master had
disabled the valve before the rogue's first frame (a loaded host: the valve's set-point timeout,
an EMCY) has its reason and cycles not judged (:attr:`RogueCanopenResult.preempted`). ``python -m
ehpss_hil.reliability.rogue_cia408 --trial DIR --case CASE`` runs one trial and prints it.
"""

from __future__ import annotations

import argparse
import struct
import sys
import time
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any, NamedTuple

from .. import PROJECT_ROOT
from ..config import BusConfig
from ..protocol.cia408 import cobid
from ..protocol.cia408.objects import BIT_D, NmtCommand
from .procs import PY, Trial, read_json_object
from .table import Row, Summary

CONTROLLER_YAML = PROJECT_ROOT / "configs" / "controller-cia408.yaml"
EMULATOR_YAML = PROJECT_ROOT / "configs" / "emulator-cia408.yaml"
#: the piston's largest deviation from x_d (m) and the controller cycles from the rogue's first
#: frame to the fail-safe command that the issue sets as the target
MAX_DEVIATION_M = 2e-3
MAX_FAILSAFE_CYCLES = 3
#: the valve node of the shipped configs and the rogue's frame rate (Hz)
VALVE = 32
ROGUE_RATE_HZ = 1000.0
#: the control word asking for DEVICE_MODE_ACTIVE (D+H+M)
ACTIVE_WORD = 0x0007
#: the encoder's position value step (m) of the shipped EDS (0x6005.1 = 100 nm)
ENCODER_STEP_M = 1e-7
#: how long a process of a trial may take to start or end (s): a hang guard only (the vcan VM
#: runs Python ~10× slower than the host)
STARTUP_LIMIT_S = 300.0
#: the settings of a trial on a host where Python runs ~10× slower and the processes share two
#: slow cores (the vcan VM): both loops at 50 Hz (the emulator too: the piston moves for one such
#: period of the rogue's +100 % before the master shuts the valve out), no starvation fault, and
#: the valve's and the master's timeouts at their largest, far beyond that host's stalls, so that
#: only the rogue makes the master disable the valve
SLOW_HOST: dict[str, Any] = {
    "rate_hz": 50.0,
    "watchdog.timeout_cycles": 100,
    "watchdog.starvation_late_fraction": 1.0,
    "cia408.setpoint_timeout_ms": 65535,
    "cia408.master_heartbeat_timeout_ms": 65535,
    "cia408.node_heartbeat_timeout_ms": 65535,
}


class RogueCase(NamedTuple):
    """What the rogue sends: ``data`` on ``can_id``, once or (``repeat``) at
    :data:`ROGUE_RATE_HZ`; and the controller's fail-safe reason expected. ``own``: the
    controller sends such frames itself (the SYNC), so its log cannot show when the rogue's
    first one reached it."""

    what: str
    can_id: int
    data: bytes
    repeat: bool
    reason: str
    own: bool = False


CASES: dict[str, RogueCase] = {
    "rpdo": RogueCase(
        "the valve's RPDO 1: ACTIVE, +100 %",
        cobid.RPDO1 + VALVE,
        bytes.fromhex("07000040"),
        True,
        "ID_COLLISION",
    ),
    "nmt-stop": RogueCase(
        "one NMT Stop of the valve", cobid.NMT, bytes([NmtCommand.STOP, VALVE]), False, "ID_COLLISION"
    ),
    "sync": RogueCase("a second SYNC producer", cobid.SYNC, b"", True, "ID_COLLISION", own=True),
    "short-rpdo": RogueCase(
        "the valve's RPDO 1, 2 of 4 bytes", cobid.RPDO1 + VALVE, bytes.fromhex("0700"), True, "ID_COLLISION"
    ),
    "short-tpdo": RogueCase(
        "the valve's TPDO 1, 2 of 4 bytes", cobid.TPDO1 + VALVE, bytes.fromhex("0f00"), True, "PDO_ERROR"
    ),
}


def send_rogue(case: str, seconds: float, bus_cfg: BusConfig) -> tuple[int, float, float]:
    """The case's frames (once, or at :data:`ROGUE_RATE_HZ` for ``seconds`` on an
    absolute-deadline grid); returns (frames sent, wall-clock time before the first was sent
    and once its send returned, s)."""
    import can

    from ..bus import open_bus

    c = CASES[case]
    msg = can.Message(arbitration_id=c.can_id, data=c.data, dlc=len(c.data), is_extended_id=False)
    bus = open_bus(bus_cfg)
    n, first, delivered = 0, 0.0, 0.0
    try:
        period = 1.0 / ROGUE_RATE_HZ
        nxt = time.monotonic()
        end = nxt + (seconds if c.repeat else 0.0)
        while n == 0 or nxt < end:
            if n == 0:
                first = time.time()
            bus.send(msg)
            if n == 0:
                delivered = time.time()
            n += 1
            nxt += period
            time.sleep(max(0.0, nxt - time.monotonic()))
    finally:
        bus.shutdown()
    return n, first, delivered


@dataclass
class RogueCanopenResult:
    """What the controller and the emulated valve did about the rogue."""

    case: str
    sent: int = 0
    #: wall-clock time (s) before the rogue's first frame was sent, and once its send returned
    first_s: float = 0.0
    delivered_s: float = 0.0
    controller: dict[str, Any] = field(default_factory=dict)
    emulator: dict[str, Any] = field(default_factory=dict)
    #: the largest |x − x_d| (m) over the run and the samples, from PLANT_TRUTH ("truth") or
    #: the encoder's position value ("encoder")
    max_deviation_m: float = float("nan")
    samples: int = 0
    source: str = ""
    #: the controller's RPDOs from its receipt of the rogue's first frame to the first asking
    #: for DISABLED
    failsafe_cycles: int | None = None
    #: the master asked for DISABLED before the rogue's first frame (its own fault came first)
    preempted: bool = False
    exits: dict[str, int | None] = field(default_factory=dict)
    error: str = ""

    @property
    def reason(self) -> str | None:
        return self.controller.get("failsafe_reason")

    @property
    def expected_reason(self) -> str:
        return CASES[self.case].reason

    @property
    def ok(self) -> bool:
        """The expected reason within :data:`MAX_FAILSAFE_CYCLES` (unless :attr:`preempted`),
        the piston within :data:`MAX_DEVIATION_M` of x_d, both exits 0."""
        judged = self.preempted or (
            self.reason == self.expected_reason
            and self.failsafe_cycles is not None
            and self.failsafe_cycles <= MAX_FAILSAFE_CYCLES
        )
        return (
            not self.error
            and self.sent > 0
            and judged
            and self.samples > 0
            and self.max_deviation_m <= MAX_DEVIATION_M
            and all(v == 0 for v in self.exits.values())
        )

    def line(self) -> str:
        """One line of figures."""
        cia = self.controller.get("cia408") or {}
        valve = (self.emulator.get("nodes") or {}).get(f"ValveNode:{VALVE}", {})
        return (
            f"{self.case}: rogue sent {self.sent}; controller {self.controller.get('state')}/"
            f"{self.reason} after {self.failsafe_cycles} cycle(s), shut out {cia.get('shut_out')}"
            f" ({cia.get('fault')}); valve {self.emulator.get('valve_state')} NMT "
            f"{valve.get('nmt')}; piston max |x − x_d| {self.max_deviation_m * 1e3:.3f} mm "
            f"({self.source}, {self.samples} samples); exits {self.exits}"
            + ("; the master had disabled the valve before the rogue (not judged)" if self.preempted else "")
            + (f"; error: {self.error}" if self.error else "")
        )


def _piston(log: Path) -> tuple[float, int, str]:
    """(max |x| (m), samples, source) from the emulator's log: PLANT_TRUTH, else the encoder's
    position value (x_d is 0 in the trial)."""
    from ..canlog import BadLines, read_log
    from ..codec import FrameCodec

    codec = FrameCodec()
    truth_id, enc_id = codec.can_id("PLANT_TRUTH"), cobid.TPDO1 + VALVE + 1
    truth, enc = [0.0, 0], [0.0, 0]
    for msg in read_log(log, bad=BadLines()):
        if msg.arbitration_id == truth_id:
            d = codec.classify(msg)
            if d.values is not None:
                truth = [max(truth[0], abs(float(d.values["Position"]))), truth[1] + 1]
        elif msg.arbitration_id == enc_id and len(msg.data) == 4:
            x = struct.unpack("<i", bytes(msg.data))[0] * ENCODER_STEP_M
            enc = [max(enc[0], abs(x)), enc[1] + 1]
    if truth[1]:
        return truth[0], int(truth[1]), "truth"
    return enc[0], int(enc[1]), "encoder"


def _disabled_before(log: Path, first_s: float) -> bool:
    """The controller's log: its last RPDO sent before ``first_s`` did not ask for ACTIVE (its
    own fail-safe came before the rogue)."""
    from ..canlog import BadLines, read_log

    last: tuple[float, int] | None = None  # (send time s, control word)
    for msg in read_log(log, bad=BadLines()):
        if msg.arbitration_id == cobid.RPDO1 + VALVE and len(msg.data) == 4 and msg.timestamp < first_s:
            word = struct.unpack_from("<H", bytes(msg.data))[0]
            if last is None or msg.timestamp >= last[0]:
                last = (msg.timestamp, word)
    return last is not None and last[1] != ACTIVE_WORD


def _receipt(log: Path, res: RogueCanopenResult) -> float:
    """When the rogue's first frame reached the controller (s, wall clock): its receive time in
    the controller's log (the bus's receive stamp) for the first frame of the case at or after
    the rogue's send; for a frame the controller sends itself (``own``), or none logged, the
    time the rogue's send returned. A loaded host may hold the rogue between its clock and its
    send for many of the controller's cycles: counted from the rogue's clock, those cycles
    would be the host's, not the controller's."""
    from ..canlog import BadLines, read_log

    c = CASES[res.case]
    if not c.own:
        for msg in read_log(log, bad=BadLines()):
            if msg.arbitration_id == c.can_id and bytes(msg.data) == c.data and msg.timestamp >= res.first_s:
                return float(msg.timestamp)
    return res.delivered_s


def _failsafe_cycles(log: Path, since_s: float, rogue: bytes) -> int | None:
    """The controller's RPDOs (its log: timestamps of its sends) from ``since_s`` up to and
    including the first asking for DISABLED; the rogue's own RPDOs (``rogue`` data) left out."""
    from ..canlog import BadLines, read_log

    n = 0
    for msg in read_log(log, bad=BadLines()):
        if msg.arbitration_id != cobid.RPDO1 + VALVE or msg.timestamp < since_s or len(msg.data) != 4:
            continue
        if bytes(msg.data) == rogue:
            continue
        n += 1
        if struct.unpack_from("<H", bytes(msg.data))[0] == BIT_D:
            return n
    return None


def rogue_cia408_trial(
    out: Path,
    case: str,
    rogue_s: float = 1.0,
    duration_s: float = 6.0,
    truth: bool = True,
    socketcan: str | None = None,
    slow: bool = False,
) -> RogueCanopenResult:
    """Controller + emulator (``duration_s`` of plant time; ``truth``: with PLANT_TRUTH) and
    ``rogue_s`` of the rogue (a single frame for ``nmt-stop``) once the controller is ACTIVE.
    ``socketcan``: on that SocketCAN channel (vcan0) in this network namespace instead of the
    configs' embedded bus in a private one. ``slow`` (the vcan VM): with :data:`SLOW_HOST`, and
    the emulator runs until the valve has taken the master's NMT Stop (then SIGTERM), not for
    ``duration_s``: the controller's start there can outlast any fixed duration."""
    from ..schema import load_yaml

    res = RogueCanopenResult(case)
    bus = (load_yaml(CONTROLLER_YAML) or {}).get("bus", {})
    common: dict[str, Any] = {"rate_hz": SLOW_HOST["rate_hz"]} if slow else {}
    rogue_bus = ["--channel", str(bus.get("channel", BusConfig().channel))]
    if socketcan is not None:
        common |= {"bus.interface": "socketcan", "bus.channel": socketcan}
        rogue_bus = ["--interface", "socketcan", "--channel", socketcan]
    with Trial(out, netns=socketcan is None) as t:
        ctl = t.controller(
            {
                "reference": {"kind": "step", "amplitude_m": 0.0},
                "watchdog.timeout_cycles": 10,
                **common,
                **(SLOW_HOST if slow else {}),
            },
            base=CONTROLLER_YAML,
        )
        args = ["--truth"] if truth else []
        if not slow:  # slow: the emulator runs until it is stopped (the controller may start longer)
            args += ["--duration", repr(duration_s)]
        emu = t.emulator(common, *args, base=EMULATOR_YAML)
        if not ctl.wait_text("first sensor data", STARTUP_LIMIT_S):
            res.error = "controller had no sensor data"
            return res
        argv = [PY, "-m", "ehpss_hil.reliability.rogue_cia408", "--case", case, "--seconds", repr(rogue_s)]
        rogue = t.spawn("rogue", [*argv, *rogue_bus])
        rogue.wait(STARTUP_LIMIT_S + rogue_s)
        try:
            words = rogue.text().split()
            res.sent, res.first_s, res.delivered_s = (
                int(words[words.index("sent") + 1]),
                float(words[words.index("first") + 1]),
                float(words[words.index("delivered") + 1]),
            )
        except (ValueError, IndexError):
            res.error = f"rogue: {rogue.text()[-200:]}"
        if slow:  # stopped once the master shut the valve out and the valve took the NMT Stop
            ctl.wait_text(f"valve {VALVE} shut out", STARTUP_LIMIT_S)
            emu.wait_text(f"node {VALVE}: NMT OPERATIONAL -> STOPPED", STARTUP_LIMIT_S)
            res.exits["emulator"] = emu.terminate()
        else:
            res.exits["emulator"] = emu.wait(STARTUP_LIMIT_S + duration_s)
        res.exits["controller"] = ctl.terminate()
    res.controller = read_json_object(out / "controller.json")
    res.emulator = read_json_object(out / "emulator.json")
    res.max_deviation_m, res.samples, res.source = _piston(out / "emulator.log")
    receipt = _receipt(out / "controller.log", res)
    res.failsafe_cycles = _failsafe_cycles(out / "controller.log", receipt, CASES[case].data)
    res.preempted = _disabled_before(out / "controller.log", res.first_s)
    return res


def cia408_rogue_rows(results: list[RogueCanopenResult], s: Summary) -> list[Row]:
    """One row per rogue case (``ehpss-hil bench faults``)."""
    rows = []
    for r in results:
        s.crashes += sum(v not in (0, None) for v in r.exits.values())
        c = CASES[r.case]
        rows.append(
            Row(
                "cia408 rogue node",
                f"{c.what}{' at 1 kHz' if c.repeat else ''}, {r.sent} sent",
                ("(valve disabled before the rogue: reason not judged) " if r.preempted else "")
                + f"controller {r.reason} after {r.failsafe_cycles} cycle(s); piston max |x − x_d| "
                f"{r.max_deviation_m * 1e3:.3f} mm ({r.source}); exits "
                f"{'/'.join(str(v) for v in r.exits.values())}" + (f"; error: {r.error}" if r.error else ""),
                f"{r.expected_reason} ≤ {MAX_FAILSAFE_CYCLES} cycles, "
                f"|x − x_d| ≤ {MAX_DEVIATION_M * 1e3:g} mm",
                r.ok,
            )
        )
    return rows


def main(argv: list[str] | None = None) -> int:
    """``python -m ehpss_hil.reliability.rogue_cia408``: be the rogue (print ``sent N first
    T delivered T``), or with ``--trial DIR`` run one whole trial and print its figures."""
    p = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    p.add_argument("--case", choices=sorted(CASES), required=True)
    p.add_argument("--seconds", type=float, default=1.0)
    p.add_argument("--interface", choices=("udp_multicast", "socketcan"), default=BusConfig().interface)
    p.add_argument("--channel", default=BusConfig().channel)
    p.add_argument("--port", type=int, default=BusConfig().port)
    p.add_argument("--trial", type=Path, help="run a whole trial in this directory")
    p.add_argument("--no-truth", action="store_true", help="trial: the piston from the encoder")
    p.add_argument("--socketcan", metavar="CHANNEL", help="trial: on this SocketCAN channel (vcan0)")
    p.add_argument("--slow", action="store_true", help="trial: settings for a slow host (the vcan VM)")
    a = p.parse_args(argv)
    if a.trial is not None:
        res = rogue_cia408_trial(
            a.trial, a.case, rogue_s=a.seconds, truth=not a.no_truth, socketcan=a.socketcan, slow=a.slow
        )
        print(res.line())
        print("PASS" if res.ok else "FAIL")
        return 0 if res.ok else 1
    bus = BusConfig(interface=a.interface, channel=a.channel, port=a.port)
    n, first, delivered = send_rogue(a.case, a.seconds, bus)
    print(f"sent {n} first {first!r} delivered {delivered!r}", flush=True)
    return 0


if __name__ == "__main__":
    sys.exit(main())
