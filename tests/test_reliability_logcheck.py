"""The reliability suite's log measurements on hand-made logs: partial lines, missing frames,
cycles to the fail-safe, watchdog trips without a real timeout, the emulator's command timeout."""

from __future__ import annotations

from pathlib import Path

from ehpss_hil.codec import FrameCodec
from ehpss_hil.protocol.failsafe import FailsafeReason
from ehpss_hil.reliability.logcheck import (
    Cycle,
    LogFile,
    audit_watchdog,
    compare,
    controller_cycles,
    cycles_to_safe,
    emulator_safe,
    read_candump,
)
from ehpss_hil.runtime.lifecycle import State

CODEC = FrameCodec()


def _line(can_id: int, data: bytes, t: float = 1.0) -> str:
    return f"({t:017.6f}) can0 {can_id:03X}#{data.hex().upper()}\n"


def test_partial_and_malformed_lines_are_found(tmp_path: Path) -> None:
    p = tmp_path / "x.log"
    p.write_text(_line(0x110, b"\x01" * 8) + "garbage\n" + _line(0x111, b"\x02" * 8)[:20])
    lf = read_candump(p)
    assert lf.frames == [(0x110, b"\x01" * 8)]
    assert lf.bad_lines == 2 and not lf.complete
    p.write_text(_line(0x110, b"") + _line(0x701, b"\x05"))
    lf = read_candump(p)
    assert lf.frames == [(0x110, b""), (0x701, b"\x05")] and lf.bad_lines == 0 and lf.complete


def test_compare_counts_missing_and_extra_frames() -> None:
    ref = [(1, bytes([i])) for i in range(10)]
    assert compare(ref[3:], ref).missing == 0  # joined late: not missing
    c = compare(ref[3:5] + ref[6:], ref)
    assert (c.missing, c.extra) == (1, 0)
    assert compare(ref[:7], ref).missing == 3  # the tail is missing ...
    assert compare(ref[:7], ref, to_end=False).missing == 0  # ... unless it stopped listening
    assert compare([*ref, (2, b"x")], ref).extra == 1


def _cycles(pattern: str) -> list[Cycle]:
    """``F``: fresh and enabled, ``s``: stale and enabled, ``Z``: stale and 0 A Enable 0,
    ``z``: fresh and Enable 0."""
    return [Cycle(ch in "Fs", 0.0 if ch in "Zz" else 1e-4, ch in "Fz", 0) for ch in pattern]


def test_cycles_to_safe_and_watchdog_audit() -> None:
    good = _cycles("FFFFssZZZZ")  # trips on the 3rd stale cycle
    assert cycles_to_safe(good) == 3
    a = audit_watchdog(good, 3, stopped=False)
    assert (a.trips, a.real_timeouts, a.spurious, a.missed, a.at_end) == (1, 1, 0, 0, 1)
    early = _cycles("FFFFsZZ")  # tripped after 2 stale cycles: spurious
    assert audit_watchdog(early, 3, stopped=False).spurious == 1
    late = _cycles("FFFFsssssZ")  # 5 stale cycles still enabled: missed
    a = audit_watchdog(late, 3, stopped=False)
    assert a.missed >= 1 and cycles_to_safe(late) == 6
    recovered = _cycles("FFsssZZzzzFFFF")
    a = audit_watchdog(recovered, 3, stopped=False)
    assert (a.trips, a.spurious, a.at_end) == (1, 0, 0)
    assert cycles_to_safe(_cycles("FFFFssss")) is None  # never safe


def test_watchdog_audit_counts_skipped_periods() -> None:
    """An overrun's skipped periods (CycleCount gap) are cycles without data: a trip on the fresh
    cycle after 3 of them (3-cycle watchdog) or after 16 (LOOP_OVERRUN) is real."""
    for skipped, timeout in ((3, 3), (16, 100)):
        cyc = _cycles("FFFFzzz")
        cyc[4].skipped = skipped
        a = audit_watchdog(cyc, timeout, stopped=False)
        assert (a.trips, a.spurious) == (1, 0), (skipped, a)
    cyc = _cycles("FFFFFF")
    cyc[4].skipped = 2  # fewer than the timeout, then fresh: nothing due
    assert audit_watchdog(cyc, 3, stopped=False).missed == 0


def _controller_log(
    tmp: Path, fresh: list[bool], enable: list[bool], status: dict[int, FailsafeReason] | None = None
) -> LogFile:
    """A controller's log: cycle i consumed a SENSOR_POS if ``fresh[i]``, sent VALVE_CMD with
    ``enable[i]``, then CTRL_STATUS (state FAULT) with ``status[i]`` where given."""
    tx, rx = FrameCodec(), FrameCodec()
    lines = []
    for i, (f, en) in enumerate(zip(fresh, enable, strict=True)):
        pos = tx.encode("SENSOR_POS", {"Position": 1e-4 * i, "Spool": 0.0}).data
        if f:
            lines.append(_line(CODEC.can_id("SENSOR_POS"), bytes(pos)))
        cmd = rx.encode(
            "VALVE_CMD", {"CurrentSetpoint": 1e-4 if en else 0.0, "Enable": int(en), "CycleCount": i}
        ).data
        lines.append(_line(CODEC.can_id("VALVE_CMD"), bytes(cmd)))
        if status and i in status:
            st = rx.encode("CTRL_STATUS", {"State": State.FAULT, "FailsafeReason": status[i]}).data
            lines.append(_line(CODEC.can_id("CTRL_STATUS"), bytes(st)))
    p = tmp / "ctl.log"
    p.write_text("".join(lines))
    return read_candump(p)


def test_controller_cycles_from_a_log(tmp_path: Path) -> None:
    fresh = [True] * 5 + [False] * 6
    enable = [True] * 7 + [False] * 4  # 3 stale cycles (5, 6, 7), Enable 0 from cycle 7
    cyc = controller_cycles(_controller_log(tmp_path, fresh, enable))
    assert [c.fresh for c in cyc] == fresh and [c.enable for c in cyc] == enable
    assert cycles_to_safe(cyc) == 3
    # five sensor samples lost in a row: the sixth frame's counter jumps by 6 (WRONG_SEQUENCE)
    fresh = [True, True] + [False] * 5 + [True, True]
    cyc = controller_cycles(_controller_log(tmp_path, fresh, [True] * 9))
    assert [c.fresh for c in cyc] == [True, True] + [False] * 6 + [True]
    assert cyc[7].e2e_bad == 1


def test_rejections_before_the_first_command_are_not_the_first_cycles(tmp_path: Path) -> None:
    """A loop that started late drains a backlog in cycles that send no command yet (here 11
    repeated SENSOR_POS frames, REPEATED): the log cannot tell which cycle drained them, so the
    first command's cycle is not given them — 11 ≥ ``max_e2e_errors`` would make the next
    stale cycle a timeout the controller "missed" (a CI run under load, kill -9 of the emulator)."""
    tx, rx = FrameCodec(), FrameCodec()
    pos = bytes(tx.encode("SENSOR_POS", {"Position": 1e-4, "Spool": 0.0}).data)
    lines = [_line(CODEC.can_id("SENSOR_POS"), pos) for _ in range(12)]
    for i in range(2):
        cmd = rx.encode("VALVE_CMD", {"CurrentSetpoint": 1e-4, "Enable": 1, "CycleCount": i}).data
        lines.append(_line(CODEC.can_id("VALVE_CMD"), bytes(cmd)))
    p = tmp_path / "ctl.log"
    p.write_text("".join(lines))
    cyc = controller_cycles(read_candump(p))
    assert [(c.fresh, c.e2e_bad) for c in cyc] == [(True, 0), (False, 0)]
    assert audit_watchdog(cyc, 3, stopped=False).missed == 0


def test_a_trip_on_fresh_data_is_starved_only_when_the_controller_says_loop_overrun(tmp_path: Path) -> None:
    """Enable drops at cycle 4 with every sample fresh (no timeout the log shows): spurious,
    unless the first CTRL_STATUS while disabled gives LOOP_OVERRUN (the loop starved); a
    status sent after enabling again says nothing about that trip."""
    fresh = [True] * 12
    enable = [True] * 4 + [False] * 4 + [True] * 4
    for status, want in (
        ({5: FailsafeReason.LOOP_OVERRUN}, (0, 1)),
        ({5: FailsafeReason.SENSOR_TIMEOUT, 6: FailsafeReason.LOOP_OVERRUN}, (1, 0)),
        ({9: FailsafeReason.LOOP_OVERRUN}, (1, 0)),  # after Enable 1 again
        ({}, (1, 0)),
    ):
        cyc = controller_cycles(_controller_log(tmp_path, fresh, enable, status))
        a = audit_watchdog(cyc, 3, stopped=False)
        assert (a.trips, a.real_timeouts, (a.spurious, a.starved)) == (1, 0, want), status


def test_emulator_timeout_and_zero_current_from_a_log(tmp_path: Path) -> None:
    tx, rx = FrameCodec(), FrameCodec()
    lines = []
    for k in range(30):
        if k < 10:
            cmd = rx.encode("VALVE_CMD", {"CurrentSetpoint": 2e-4, "Enable": 1}).data
            lines.append(_line(CODEC.can_id("VALVE_CMD"), bytes(cmd)))
        since = max(0, k - 9)
        aux = tx.encode(
            "SENSOR_AUX",
            {
                "LoadPressure": 0.0,
                "CmdTimeout": int(since >= 10),
                "CoilCurrent": 2e-4 if since <= 10 else 0.0,
            },
        ).data
        lines.append(_line(CODEC.can_id("SENSOR_AUX"), bytes(aux)))
    p = tmp_path / "emu.log"
    p.write_text("".join(lines))
    s = emulator_safe(read_candump(p))
    assert (s.periods_to_timeout, s.periods_to_zero_current) == (10, 10)
