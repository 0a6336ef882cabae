"""Read a process's candump log strictly and measure from it: completeness against another log,
the controller's and the emulator's way to their safe state, and the watchdog's trips.

Each process logs every frame it receives when it drains it (before acting on it) and every
frame it sends when it sends it, in one thread, so the log's order is the process's own order:
the frames a controller cycle consumed precede that cycle's VALVE_CMD, and the VALVE_CMD an
emulator period accepted precedes that period's SENSOR_AUX. Cycles and periods are counted as
the processes count them: one executed controller cycle per VALVE_CMD, one executed emulator
period per SENSOR_AUX (periods skipped by an overrun send nothing and tick no timeout).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field
from pathlib import Path

import can

from ..codec import FrameCodec, Verdict
from ..control.sampleclock import RESYNC_SAMPLES
from ..protocol.failsafe import FailsafeReason

#: one classic-CAN ``candump -L`` line (our logs hold no remote or FD frames)
_LINE = re.compile(rb"\(\d{10}\.\d{6}\) \S+ ([0-9A-F]{3}|[0-9A-F]{8})#((?:[0-9A-F]{2}){0,8})")
_E2E_BAD = (Verdict.CRC_ERROR, Verdict.REPEATED, Verdict.WRONG_SEQUENCE, Verdict.BAD_DLC)

Frame = tuple[int, bytes]


@dataclass
class LogFile:
    """A candump ``-L`` file: its frames in order, lines that are not a whole frame line, and
    whether the last line is complete (ends with a newline)."""

    path: Path
    frames: list[Frame] = field(default_factory=list)
    bad_lines: int = 0
    complete: bool = True

    def only(self, ids: set[int]) -> list[Frame]:
        """The frames with these IDs, in order."""
        return [f for f in self.frames if f[0] in ids]


def read_candump(path: Path) -> LogFile:
    """Parse ``path`` line by line (a missing file reads as empty)."""
    lf = LogFile(Path(path))
    try:
        raw = Path(path).read_bytes()
    except FileNotFoundError:
        return lf
    lines = raw.split(b"\n")
    if lines and lines[-1] == b"":
        lines.pop()
    elif lines:
        lf.complete = False
    for line in lines:
        m = _LINE.fullmatch(line)
        if m is None:
            lf.bad_lines += 1
            continue
        lf.frames.append((int(m.group(1), 16), bytes.fromhex(m.group(2).decode())))
    return lf


@dataclass(frozen=True)
class Completeness:
    """A log's frames against a reference log's: ``missing`` frames of the reference (from the
    first frame both hold) absent from the log, ``extra`` frames the reference does not hold."""

    compared: int
    missing: int
    extra: int


def compare(log: list[Frame], reference: list[Frame], to_end: bool = True) -> Completeness:
    """Order-preserving match of ``log`` against ``reference`` from ``log``'s first frame (a
    process may join the bus after the reference logger) to the reference's end, or with
    ``to_end`` False to ``log``'s last frame (a process that stopped listening earlier)."""
    if not log:
        return Completeness(0, len(reference) if to_end else 0, 0)
    try:
        i = reference.index(log[0])
    except ValueError:
        return Completeness(len(log), len(reference), len(log))
    j = missing = compared = 0
    for f in reference[i:]:
        if j == len(log) and not to_end:
            break
        compared += 1
        if j < len(log) and log[j] == f:
            j += 1
        else:
            missing += 1
    return Completeness(compared, missing, len(log) - j)


def _verdict(codec: FrameCodec, f: Frame) -> Verdict:
    """How a receiver with ``codec``'s sequence state classifies a received frame."""
    return codec.classify(can.Message(arbitration_id=f[0], data=f[1], is_extended_id=False)).verdict


def decode_own(codec: FrameCodec, name: str, f: Frame) -> dict[str, float]:
    """The values of a frame the process sent itself (no sequence check: its own counters)."""
    return codec.message(name).decode(f[1], decode_choices=False)  # type: ignore[return-value]


@dataclass
class Cycle:
    """One executed controller cycle: its VALVE_CMD and what it consumed before it."""

    enable: bool
    current_a: float
    fresh: bool
    e2e_bad: int
    #: grid periods skipped before it (the CycleCount gap): cycles without data
    skipped: int = 0
    #: the FailsafeReason of a CTRL_STATUS sent after this cycle's VALVE_CMD (None: none sent)
    status_reason: FailsafeReason | None = None


def controller_cycles(log: LogFile, codec: FrameCodec | None = None) -> list[Cycle]:
    """The controller's executed cycles from its own log (verdicts re-derived in log order);
    E2E rejections logged before its first VALVE_CMD are not counted (cycles that sent no
    command drained them)."""
    codec = codec or FrameCodec()
    pos, aux, cmd, status = (
        codec.can_id(n) for n in ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD", "CTRL_STATUS")
    )
    out: list[Cycle] = []
    fresh, bad = False, 0
    last: int | None = None
    for f in log.frames:
        if f[0] in (pos, aux):
            v = _verdict(codec, f)
            fresh = fresh or (f[0] == pos and v.usable)
            bad += v in _E2E_BAD
        elif f[0] == cmd:
            vals = decode_own(codec, "VALVE_CMD", f)
            cc = int(vals["CycleCount"])
            skipped = 0 if last is None else (cc - last - 1) % 65536
            if last is None:
                # the loop's cycles before its first command (waiting for sensor data) send none:
                # which of them drained a rejected frame the log cannot tell, and each counted
                # its own, so none is given to the first command's cycle
                bad = 0
            last = cc
            out.append(Cycle(bool(vals["Enable"]), float(vals["CurrentSetpoint"]), fresh, bad, skipped))
            fresh, bad = False, 0
        elif f[0] == status and out:
            out[-1].status_reason = _reason(int(decode_own(codec, "CTRL_STATUS", f)["FailsafeReason"]))
    return out


def _reason(value: int) -> FailsafeReason | None:
    """The FailsafeReason of a CTRL_STATUS value (None: a value the DBC does not name)."""
    try:
        return FailsafeReason(value)
    except ValueError:
        return None


def cycles_to_safe(cycles: list[Cycle]) -> int | None:
    """Executed cycles from the last one with a usable sensor frame to the first VALVE_CMD from
    which on every command is 0 A with Enable 0 (None: never safe after it)."""
    last_fresh = max((i for i, c in enumerate(cycles) if c.fresh), default=None)
    if last_fresh is None:
        return None
    first_safe = len(cycles)
    for i in range(len(cycles) - 1, last_fresh - 1, -1):
        c = cycles[i]
        if c.enable or c.current_a != 0.0:
            break
        first_safe = i
    return None if first_safe == len(cycles) else first_safe - last_fresh


@dataclass(frozen=True)
class WatchdogAudit:
    """Trips seen in a controller log (Enable 1 → 0) against real timeouts: ``timeout_cycles``
    executed cycles in a row without a usable SENSOR_POS (or ``max_e2e_errors`` E2E failures).
    ``at_end``: trips after which no usable sensor frame came any more (the peer had stopped);
    ``starved``: trips with no timeout in the log that the controller reported as LOOP_OVERRUN
    (its own loop starved: due, but not from the data; not counted in ``spurious``)."""

    cycles: int
    trips: int
    real_timeouts: int
    spurious: int
    missed: int
    at_end: int = 0
    starved: int = 0


def audit_watchdog(
    cycles: list[Cycle], timeout_cycles: int, max_e2e_errors: int = 10, stopped: bool = True
) -> WatchdogAudit:
    """Every trip must follow a real timeout and every real timeout while active must trip.
    Periods skipped by an overrun (CycleCount gaps) count as cycles without data; more than
    ``RESYNC_SAMPLES`` at once is due (LOOP_OVERRUN). Stale frames and starvation cannot be
    told from the log (they depend on the moment of each drain): such a trip shows as spurious,
    unless the first CTRL_STATUS the controller sent while disabled gives LOOP_OVERRUN
    (``starved``). ``stopped``: the last VALVE_CMD is the shutdown command (not a trip)."""
    cyc = cycles[:-1] if stopped and cycles else cycles
    stale = errors = real = spurious = missed = starved = 0
    trips: list[int] = []
    for i, c in enumerate(cyc):
        stale += c.skipped  # an overrun's skipped periods are cycles without data
        skip_due = stale >= timeout_cycles or c.skipped > RESYNC_SAMPLES
        stale = 0 if c.fresh else stale + 1
        errors = c.e2e_bad if c.fresh else errors + c.e2e_bad
        due = skip_due or stale >= timeout_cycles or errors >= max_e2e_errors
        active_before = i > 0 and cyc[i - 1].enable
        if not active_before:
            continue
        real += due
        if not c.enable:
            trips.append(i)
            if not due:
                if _reported_reason(cyc, i) is FailsafeReason.LOOP_OVERRUN:
                    starved += 1
                else:
                    spurious += 1
        elif due:
            missed += 1
    last_fresh = max((i for i, c in enumerate(cyc) if c.fresh), default=-1)
    at_end = sum(t > last_fresh for t in trips)
    return WatchdogAudit(len(cyc), len(trips), real, spurious, missed, at_end, starved)


def _reported_reason(cycles: list[Cycle], trip: int) -> FailsafeReason | None:
    """The FailsafeReason of the first CTRL_STATUS sent from cycle ``trip`` on while the
    controller stayed disabled (None: it sent none before enabling again)."""
    for c in cycles[trip:]:
        if c.enable:
            return None
        if c.status_reason is not None:
            return c.status_reason
    return None


def last_status(
    log: LogFile, codec: FrameCodec | None = None, before_last: bool = True
) -> tuple[str, str] | None:
    """(State, FailsafeReason) names of the controller's last CTRL_STATUS (with
    ``before_last``: the one before the shutdown status)."""
    from ..protocol.failsafe import FailsafeReason
    from ..runtime.lifecycle import State

    codec = codec or FrameCodec()
    st = [f for f in log.frames if f[0] == codec.can_id("CTRL_STATUS")]
    if len(st) < 1 + before_last:
        return None
    vals = decode_own(codec, "CTRL_STATUS", st[-1 - before_last])
    return State(int(vals["State"])).name, FailsafeReason(int(vals["FailsafeReason"])).name


@dataclass(frozen=True)
class EmulatorSafe:
    """Emulator periods from the one that accepted the last valid VALVE_CMD to CmdTimeout set,
    and to the applied current being 0 A (read from the next period's CoilCurrent echo)."""

    periods_to_timeout: int | None
    periods_to_zero_current: int | None


def emulator_safe(log: LogFile, codec: FrameCodec | None = None) -> EmulatorSafe:
    """Measure :class:`EmulatorSafe` from the emulator's own log."""
    codec = codec or FrameCodec()
    cmd, aux = codec.can_id("VALVE_CMD"), codec.can_id("SENSOR_AUX")
    periods: list[tuple[bool, bool, float]] = []  # (command accepted, CmdTimeout, echo A)
    got = False
    for f in log.frames:
        if f[0] == cmd:
            got = got or _verdict(codec, f).usable
        elif f[0] == aux:
            vals = decode_own(codec, "SENSOR_AUX", f)
            periods.append((got, bool(vals["CmdTimeout"]), float(vals["CoilCurrent"])))
            got = False
    k0 = max((i for i, p in enumerate(periods) if p[0]), default=None)
    if k0 is None:
        return EmulatorSafe(None, None)
    k1 = next((i for i in range(k0, len(periods)) if periods[i][1]), None)
    k2 = len(periods)
    for i in range(len(periods) - 1, k0, -1):
        if periods[i][2] != 0.0:
            break
        k2 = i
    return EmulatorSafe(None if k1 is None else k1 - k0, None if k2 == len(periods) else k2 - 1 - k0)
