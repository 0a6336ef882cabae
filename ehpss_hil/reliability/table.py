"""Rows of the ``ehpss-hil bench faults`` table, one per fuzz target, loss case or trial, and the
summary (trials, faults survived, frames fuzzed, crashes, data lost)."""

from __future__ import annotations

from dataclasses import dataclass, field

from .badinput import BadResult
from .duplicates import DupResult
from .fuzz import FuzzTally
from .hostile import DiskFullResult, ForeignResult
from .kills import KillResult, TermResult
from .loss import TARGET_LEVEL, TARGET_RATIO, LossRow
from .rogue import MAX_DEVIATION_M, RogueResult
from .stray import StrayResult

_ABBR = {
    "OK": "OK",
    "OK_SOME_LOST": "LOST",
    "REPEATED": "REP",
    "WRONG_SEQUENCE": "SEQ",
    "CRC_ERROR": "CRC",
    "BAD_DLC": "DLC",
    "UNKNOWN_ID": "UNK",
    "OUT_OF_RANGE": "RANGE",
}
_TARGET_NAME = {
    "codec": "FrameCodec.classify",
    "controller": "controller loop (mmac)",
    "emulator": "emulator command handler",
}


@dataclass
class Row:
    """One line of the table; ``ok`` None: a figure without a target."""

    fault: str
    case: str
    measured: str
    target: str = ""
    ok: bool | None = None
    #: counts toward the summary's trials / faults survived
    trial: bool = True


@dataclass
class Summary:
    """The last line of the table."""

    trials: int = 0
    survived: int = 0
    #: frames through all receivers (each frame goes through each of ``receivers``)
    frames_fuzzed: int = 0
    receivers: int = 0
    crashes: int = 0
    data_lost: int = 0
    failed: list[str] = field(default_factory=list)

    def add(self, rows: list[Row]) -> None:
        """Account the trial rows."""
        for r in rows:
            if r.trial and r.ok is not None:
                self.trials += 1
                self.survived += r.ok
                if not r.ok:
                    self.failed.append(f"{r.fault}: {r.case}")

    @property
    def ok(self) -> bool:
        return self.survived == self.trials and self.crashes == 0 and self.data_lost == 0 and not self.failed

    def line(self) -> str:
        return (
            f"summary: trials {self.trials}, faults survived {self.survived}/{self.trials}, "
            f"frames fuzzed {self.frames_fuzzed} ({self.frames_fuzzed // max(self.receivers, 1)}"
            f" × {self.receivers} receivers), crashes = {self.crashes}, data lost = "
            f"{self.data_lost}: {'PASS' if self.ok else 'FAIL'}"
        )


def fuzz_rows(tallies: list[FuzzTally], s: Summary) -> list[Row]:
    """One row per receiver: verdict counts of the frames it consumed."""
    rows = []
    for t in tallies:
        counts = "/".join(_ABBR[k] for k in t.by_verdict)
        nums = "/".join(str(n) for n in t.by_verdict.values())
        s.frames_fuzzed += t.frames
        s.receivers += 1
        s.crashes += t.crashes
        ok = (
            t.crashes == 0
            and t.mismatches == 0
            and t.acted_on_bad == 0
            and t.consumed == sum(t.by_verdict.values())
        )
        rows.append(
            Row(
                "fuzz",
                _TARGET_NAME[t.target],
                f"{t.frames} frames, {t.consumed} consumed: {counts} {nums}; "
                f"verdict≠expected {t.mismatches}, rejected but acted on "
                f"{t.acted_on_bad}, crashes {t.crashes}",
                "each counted under its verdict, none acted on, no crash",
                ok,
            )
        )
    return rows


def _pct(p: float) -> str:
    return f"{p * 100:g} %"


def loss_rows(rows: list[LossRow], s: Summary) -> list[Row]:
    """Sim and process loss cases (RMS, ratio to lossless, watchdog audit for processes)."""
    out = []
    for r in rows:
        where = "loss (sim, case 1)" if r.where == "sim" else "loss (processes)"
        case = "lossless" if r.direction == "none" else f"{r.direction} {_pct(r.loss)}"
        if r.timeout_cycles is not None:
            case += f", wd {r.timeout_cycles} cycles"
        ratio = f" ({r.ratio:.2f}× lossless)" if r.ratio is not None else ""
        measured = f"mmac RMS {r.rms_m * 1e6:.3g} µm{ratio}"
        if r.where == "processes":
            measured += " (host timing)"
        target = ""
        if r.target is not None:
            target = f"{_pct(TARGET_LEVEL)}: ≤ {TARGET_RATIO:g}× lossless"
        if r.audit is not None:
            a = r.audit
            end = f" + {a.at_end} after the emulator ended" if a.at_end else ""
            measured += (
                f"; watchdog trips {a.trips - a.at_end}{end} (real timeouts "
                f"{a.real_timeouts}, spurious {a.spurious}, missed {a.missed}"
                + (f", starved loop {a.starved}" if a.starved else "")
                + ")"
            )
            target = "trips only on real timeouts, every one trips"
            if not r.exit_ok:
                measured += "; a process ended badly"
                s.crashes += 1
        ok = r.ok if (r.audit is not None or r.target is not None) else None
        out.append(Row(where, case, measured, target, ok))
    return out


def dup_rows(results: list[DupResult], s: Summary) -> list[Row]:
    """Duplicated/reordered/burst trials."""
    rows = []
    for i, d in enumerate(results, 1):
        s.data_lost += d.frames_missing
        s.crashes += d.controller_exit not in (0, None)
        if d.error:
            rows.append(Row("dup/reorder/burst", f"#{i}", f"error: {d.error}", "", False))
            continue
        c, e = d.counted, d.expected
        rows.append(
            Row(
                "dup/reorder/burst",
                f"#{i}: {d.frames_sent} sensor frames",
                f"REP {c.get('REPEATED')}/{e.get('REPEATED')}, SEQ {c.get('WRONG_SEQUENCE')}/"
                f"{e.get('WRONG_SEQUENCE')}, LOST {c.get('OK_SOME_LOST')}/{e.get('OK_SOME_LOST')}, "
                f"OK {c.get('OK')}/{e.get('OK')} (counted/sent); {d.acted} steps acted on "
                f"{d.distinct_usable} usable samples: twice {d.acted_twice}, late {d.acted_on_late}, "
                f"not the newest {d.wrong_sample}; frames lost {d.frames_missing}",
                "counted; never acted on twice",
                d.ok,
            )
        )
    return rows


def kill_rows(results: list[KillResult], s: Summary) -> list[Row]:
    """kill -9 trials."""
    rows = []
    for k in results:
        s.data_lost += k.log.rx_missing + k.log.tx_missing
        s.crashes += k.survivor_exit not in (0, None)
        case = f"#{k.trial + 1}: kill {k.victim} at {k.at_s:.2f} s"
        if k.error:
            rows.append(Row("kill -9", case, f"error: {k.error}", "", False))
            continue
        unit = "cycles" if k.survivor == "controller" else "periods"
        if k.survivor == "controller":
            how = (k.status[1] if k.status else "no status") + (
                f", spurious trips {k.audit.spurious}" if k.audit is not None else ""
            )
        else:
            how = f"0 A applied after {k.zero_current}"
        lg = k.log
        rows.append(
            Row(
                "kill -9",
                case,
                f"{k.survivor} safe in {k.safe} {unit} ({how}); exit {k.survivor_exit}; log "
                f"{lg.frames} frames, missing {lg.rx_missing + lg.tx_missing}, extra "
                f"{lg.rx_extra + lg.tx_extra}, bad lines {lg.bad_lines + (not lg.complete)}",
                f"≤ {k.limit} {unit}; log complete",
                k.ok,
            )
        )
    return rows


def term_rows(results: list[TermResult], s: Summary) -> list[Row]:
    """SIGTERM trials."""
    rows = []
    for t in results:
        s.data_lost += sum(a.rx_missing + a.tx_missing for a in t.logs.values())
        s.data_lost += sum(max(0, n) for n in t.dropped.values())
        s.crashes += sum(v not in (0, None) for v in t.exits.values())
        case = f"#{t.trial + 1}: {t.first} first at {t.at_s:.2f} s"
        if t.error:
            rows.append(Row("SIGTERM", case, f"error: {t.error}", "", False))
            continue
        cmd = "none" if t.last_command is None else f"{t.last_command[0]:g} A Enable {t.last_command[1]}"
        missing = sum(a.rx_missing + a.tx_missing for a in t.logs.values())
        rows.append(
            Row(
                "SIGTERM",
                case,
                f"exits {'/'.join(str(v) for v in t.exits.values())}; last VALVE_CMD {cmd}"
                f"{' (reached the emulator)' if t.command_delivered else ''}; logs missing {missing}, "
                f"dropped {sum(t.dropped.values())}, closed {all(t.closed.values())}",
                "exit 0, 0 A Enable 0, logs flushed",
                t.ok,
            )
        )
    return rows


def bad_rows(results: list[BadResult], bus_frames: int, s: Summary) -> list[Row]:
    """Bad inputs grouped per file, plus the bus check."""
    rows = []
    for target in ("controller", "emulator", "scenario"):
        rs = [r for r in results if r.mutation.target == target]
        if not rs:
            continue
        good = [r for r in rs if r.ok]
        s.crashes += sum(r.exit_code not in (2, None) and r.exit_code != 0 for r in rs)
        bad = ", ".join(
            f"{r.mutation.key_path}={r.mutation.value!r} → {r.exit_code}" for r in rs if not r.ok
        )[:300]
        name = "scenario (case 1 + loss keys)" if target == "scenario" else f"{target}.yaml"
        rows.append(
            Row(
                "bad input",
                f"{name}: {len(rs)} keys",
                f"exit 2 + one line naming the key path: {len(good)}/{len(rs)}"
                + (f"; failed: {bad}" if bad else ""),
                "all",
                len(good) == len(rs),
                trial=False,
            )
        )
    s.trials += len(results)
    s.survived += sum(r.ok for r in results)
    s.failed += [f"bad input: {r.mutation.target} {r.mutation.key_path}" for r in results if not r.ok]
    rows.append(
        Row(
            "bad input",
            "bus logger beside them",
            f"frames on the bus: {bus_frames}",
            "0",
            bus_frames == 0,
            trial=False,
        )
    )
    if bus_frames:
        s.failed.append("bad input: frames reached the bus")
    return rows


def hostile_rows(
    stray: StrayResult, foreign: ForeignResult | None, disk: DiskFullResult | None, s: Summary
) -> list[Row]:
    """Stray datagrams on the bus, foreign files in ``--out``, a full disk (issue #16); None:
    the part could not run (no root for ``mount``)."""
    s.crashes += sum(v not in (0, None) for v in stray.exits.values())
    counted = ", ".join(f"{k} {v}" for k, v in stray.counted.items())
    rows = [
        Row(
            "stray datagrams",
            f"{stray.sent} sent (empty, text, msgpack int, cut map, 60 kB)",
            f"alive {sum(stray.alive.values())}/{len(stray.alive)}; exits "
            f"{'/'.join(str(v) for v in stray.exits.values())}; counted: {counted}"
            + (f"; error: {stray.error}" if stray.error else ""),
            "all alive, exit 0, each counts every one",
            stray.ok,
        )
    ]
    if foreign is not None:
        rows.append(
            Row(
                "foreign files in --out",
                f"{len(foreign.refused_lines)} line(s)",
                f"refused: exit {foreign.refused_exit}, kept "
                f"{foreign.kept_after_refusal}/4; --overwrite: exit "
                f"{foreign.overwrite_exit}, kept {foreign.kept_after_run}/4",
                "exit 2 + one line, then exit 0 (4: realtime not valid); all 4 kept",
                foreign.ok,
            )
        )
    if disk is not None:
        s.crashes += sum(v not in (0, None) for v in disk.exits.values())
        logs = "; ".join(
            f"{n} {st.written}/{st.lines} lines, {st.dropped} dropped ({', '.join(st.reasons) or '-'})"
            for n, st in disk.logs.items()
        )
        rows.append(
            Row(
                "disk full (200 kB tmpfs)",
                "controller + emulator --log",
                f"exits {'/'.join(str(v) for v in disk.exits.values())}; sidecar/file "
                f"{logs}; warned {disk.warned}, summaries "
                f"{sum(disk.summaries.values())}/2, .tmp left {len(disk.tmp_left)}, "
                f"replay exit {disk.replay_exit}" + (f"; {disk.error}" if disk.error else ""),
                "exit 0, exact counts, whole lines, warned",
                disk.ok,
            )
        )
    return rows


def rogue_rows(r: RogueResult, s: Summary) -> list[Row]:
    """A second VALVE_CMD transmitter beside the controller and the emulator (issue #16)."""
    s.crashes += sum(v not in (0, None) for v in r.exits.values())
    c, e = r.controller, r.emulator
    return [
        Row(
            "second transmitter",
            f"rogue VALVE_CMD at 1 kHz, {r.sent} sent",
            f"emulator conflicts {e.get('command_conflicts')} (foreign "
            f"{e.get('foreign_commands')}, CommandConflict {int(r.command_conflict_seen)}); "
            f"controller {c.get('state')}/{c.get('failsafe_reason')}, VALVE_CMD collisions "
            f"{r.valve_cmd_collisions}; piston max |x − x_d| {r.max_deviation_m * 1e6:.1f} µm; "
            f"exits {'/'.join(str(v) for v in r.exits.values())}"
            + (f"; error: {r.error}" if r.error else ""),
            f"valve centred, ID_COLLISION, |x − x_d| ≤ {MAX_DEVIATION_M * 1e3:g} mm",
            r.ok,
        )
    ]


def format_table(rows: list[Row]) -> str:
    """Fixed columns; the measured column is as wide as it needs to be."""
    w = [max(len(r.fault) for r in rows), max(len(r.case) for r in rows)]
    lines = [f"{'fault':<{w[0]}}  {'case':<{w[1]}}  verdict  measured  [target]"]
    for r in rows:
        v = "" if r.ok is None else ("PASS" if r.ok else "FAIL")
        tgt = f"  [{r.target}]" if r.target else ""
        lines.append(f"{r.fault:<{w[0]}}  {r.case:<{w[1]}}  {v:<7}  {r.measured}{tgt}")
    return "\n".join(lines)
