"""Duplicated, reordered and burst sensor frames against a real controller process.

A controller process (the daemon, realtime, with the probe law of :mod:`.probe`; the watchdog's
E2E burst limit lifted so that the copies do not keep it in FAULT) and the scripted peer of
:mod:`.peer` run in one private namespace. Afterwards, from the controller's
own candump log and summary:

- every frame the peer sent was received and logged (none missing, none extra);
- its verdict counters equal the counts by construction (REPEATED for each copy,
  WRONG_SEQUENCE for each late frame, OK_SOME_LOST for the frame before it);
- no sample was acted on twice (each sample number appears in at most one VALVE_CMD), no late
  (WRONG_SEQUENCE) sample was acted on, and every cycle with Enable 1 acted on exactly the newest
  usable SENSOR_POS it consumed (0 A when it had none).
"""

from __future__ import annotations

import json
from collections import Counter
from dataclasses import dataclass, field
from pathlib import Path

import can

from ..codec import FrameCodec
from .kills import summary_json
from .logcheck import LogFile, compare, decode_own, read_candump
from .probe import POSITION_STEP_M, sample_of
from .procs import PY, Trial

#: the copies are E2E errors: with the config's burst limit (10) the watchdog would hold the
#: controller in FAULT for most of the trial and little would be acted on at all
_WATCHDOG = {
    "watchdog.timeout_cycles": 10,
    "watchdog.auto_recover": True,
    "watchdog.recovery_cycles": 5,
    "watchdog.max_e2e_errors": 1_000_000,
}


@dataclass
class DupResult:
    """Counts of one trial (frames are SENSOR_POS + SENSOR_AUX)."""

    frames_sent: int = 0
    kinds: dict[str, int] = field(default_factory=dict)
    expected: dict[str, int] = field(default_factory=dict)
    counted: dict[str, int] = field(default_factory=dict)
    frames_missing: int = 0
    frames_extra: int = 0
    #: executed cycles (VALVE_CMDs) and those that acted on a sample (Enable 1, sample > 0)
    cycles: int = 0
    acted: int = 0
    distinct_usable: int = 0
    acted_twice: int = 0
    acted_on_late: int = 0
    #: cycles whose command was not the newest usable sample of that cycle
    wrong_sample: int = 0
    #: cycles the controller spent in its fail-safe (its summary): a starved host trips the
    #: watchdog, and the samples of those cycles are consumed without being acted on
    failsafe_cycles: int = 0
    controller_exit: int | None = None
    error: str = ""

    @property
    def ok(self) -> bool:
        """Counted as constructed, nothing lost, nothing acted on twice or wrongly."""
        keys = ("OK", "OK_SOME_LOST", "REPEATED", "WRONG_SEQUENCE")
        return (
            not self.error
            and self.controller_exit == 0
            and self.acted > 0
            and all(self.counted.get(k) == self.expected.get(k) for k in keys)
            and self.frames_missing
            == self.frames_extra
            == self.acted_twice
            == self.acted_on_late
            == self.wrong_sample
            == 0
        )


def _cycles(log: LogFile, codec: FrameCodec) -> list[tuple[int | None, int, bool]]:
    """Per VALVE_CMD: (newest usable sample consumed in the cycle, sample in the command,
    Enable)."""
    pos, cmd = codec.can_id("SENSOR_POS"), codec.can_id("VALVE_CMD")
    out: list[tuple[int | None, int, bool]] = []
    newest: int | None = None
    for can_id, data in log.frames:
        if can_id == pos:
            d = codec.classify(can.Message(arbitration_id=can_id, data=data, is_extended_id=False))
            if d.verdict.usable and d.values is not None:
                newest = round(float(d.values["Position"]) / POSITION_STEP_M)
        elif can_id == cmd:
            v = decode_own(codec, "VALVE_CMD", (can_id, data))
            out.append((newest, sample_of(float(v["CurrentSetpoint"])), bool(v["Enable"])))
            newest = None
    return out


def analyse(out: Path, res: DupResult) -> DupResult:
    """Fill ``res`` from the trial directory's files."""
    codec = FrameCodec()
    peer = json.loads((out / "peer.json").read_text())
    res.frames_sent, res.kinds, res.expected = peer["frames"], peer["kinds"], peer["expected"]
    late = set(peer["late"])
    ctl = read_candump(out / "controller.log")
    sensor = {codec.can_id("SENSOR_POS"), codec.can_id("SENSOR_AUX")}
    c = compare(ctl.only(sensor), read_candump(out / "sent.log").frames)
    res.frames_missing, res.frames_extra = c.missing, c.extra
    summary = summary_json(out, "controller")
    counted = summary.get("received_by_verdict")
    res.counted = dict(counted) if isinstance(counted, dict) else {}
    failsafe = summary.get("failsafe_cycles")
    res.failsafe_cycles = int(failsafe) if isinstance(failsafe, int) else 0
    cycles = _cycles(ctl, codec)[:-1]  # the last one is the shutdown command
    res.cycles = len(cycles)
    acted = [s for _, s, en in cycles if en and s > 0]
    res.acted = len(acted)
    res.acted_twice = sum(n - 1 for n in Counter(acted).values())
    res.acted_on_late = sum(s in late for s in acted)
    res.wrong_sample = sum(1 for newest, s, en in cycles if en and s != (newest or 0))
    res.distinct_usable = len({n for n, _, _ in cycles if n is not None})
    return res


def dup_trial(out: Path, samples: int = 2000, seed: int = 1) -> DupResult:
    """Run the controller (probe law) against the scripted peer; analyse the logs."""
    res = DupResult()
    try:
        with Trial(out) as t:
            ctl = t.controller(_WATCHDOG, "--controller-factory", "ehpss_hil.reliability.probe:probe_factory")
            if not ctl.wait_text(" on udp_multicast:"):
                raise RuntimeError(f"controller did not start: {ctl.text()[-500:]}")
            peer = t.spawn(
                "peer",
                [
                    PY,
                    "-m",
                    "ehpss_hil.reliability.peer",
                    "--samples",
                    str(samples),
                    "--seed",
                    str(seed),
                    "--sent",
                    str(out / "sent.log"),
                    "--summary",
                    str(out / "peer.json"),
                ],
            )
            if peer.wait(120.0) != 0:
                raise RuntimeError(f"peer failed: {peer.text()[-500:]}")
            res.controller_exit = ctl.terminate()
    except (RuntimeError, OSError) as exc:
        res.error = str(exc)
        return res
    return analyse(out, res)
