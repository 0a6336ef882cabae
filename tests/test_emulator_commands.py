"""Emulator command handling, one realtime period at a time over python-can ``virtual``
(periods are counted; nothing is timed): command timeout, rejected VALVE_CMDs, FAULT_INJECT."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import can
import pytest
from _virtual import VirtualPair

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.codec.e2e import protect
from ehpss_hil.emulation import PlantEmulation
from ehpss_hil.physics.load import load_params
from ehpss_hil.runtime.frameio import FrameIO
from ehpss_hil.scenario import Scenario
from firmware_sim.inject import InjectStatus
from firmware_sim.process import OWN_FRAMES, EmulatorOptions, EmulatorProcess

TIMEOUT_PERIODS = 10  # command_timeout_s 10 ms at 1 kHz


class Rig(VirtualPair):
    """An emulator process and a test peer on one virtual channel."""

    def __init__(self, name: str, **opts: object) -> None:
        super().__init__(name)
        self.codec = FrameCodec()  # the peer's TX counters
        self.cycle = 0  # the peer's CycleCount, one up per command like a controller's
        self.proc = EmulatorProcess(
            PlantEmulation(load_params(), Scenario(name="t", duration_s=10.0)),
            FrameIO(self.bus, FrameCodec(), OWN_FRAMES),
            EmulatorOptions(command_timeout_s=0.010, **opts),  # type: ignore[arg-type]
        )

    def cmd(self, current_a: float, enable: int = 1) -> can.Message:
        self.cycle = (self.cycle + 1) & 0xFFFF
        msg = self.codec.encode(
            "VALVE_CMD", {"CurrentSetpoint": current_a, "Enable": enable, "CycleCount": self.cycle}
        )
        self.peer.send(msg)
        return msg

    def step(self) -> tuple[float, dict[str, float]]:
        """One period; returns (applied current (A), the SENSOR_AUX values sent)."""
        applied = self.proc.step_period()
        return applied, self.newest().get("SENSOR_AUX", {})

    @property
    def verdicts(self) -> dict[Verdict, int]:
        return self.proc.codec.counts_by_name.get("VALVE_CMD", {v: 0 for v in Verdict})


@pytest.fixture
def rig(request: pytest.FixtureRequest) -> Iterator[Rig]:
    r = Rig(request.node.name)
    yield r
    r.close()


def test_starts_timed_out_then_applies_fresh_commands(rig: Rig) -> None:
    applied, aux = rig.step()
    assert applied == 0.0 and aux["CmdTimeout"] == 1
    rig.cmd(2e-4)
    applied, _ = rig.step()
    assert applied == pytest.approx(2e-4, abs=2e-7)
    _, aux = rig.step()
    assert aux["CmdTimeout"] == 0 and aux["ValveEnabled"] == 1


def _periods_until_zero(rig: Rig, limit: int = 50) -> int:
    for n in range(1, limit + 1):
        applied, _ = rig.step()
        if applied == 0.0:
            return n
    return -1


def test_command_timeout_counts_periods(rig: Rig) -> None:
    for _ in range(20):
        rig.cmd(3e-4)
        assert rig.step()[0] == pytest.approx(3e-4, abs=2e-7)
    n = _periods_until_zero(rig)
    assert abs(n - TIMEOUT_PERIODS) <= 1, n
    _, aux = rig.step()
    assert aux["CmdTimeout"] == 1 and aux["ValveEnabled"] == 0
    assert rig.proc.hold.timeouts == 1  # (it starts timed out: no command yet)
    rig.cmd(-1e-4)  # resumes on a fresh command
    assert rig.step()[0] == pytest.approx(-1e-4, abs=2e-7)


def _raw_cmd(rig: Rig, current_a: float, counter: int) -> bytes:
    """A correctly protected VALVE_CMD with any current (bypasses the encoder's range check)."""
    msg = rig.codec.message("VALVE_CMD")
    data = bytearray(
        msg.encode(
            {
                "CRC": 0,
                "Counter": 0,
                "Enable": 1,
                "CurrentSetpoint": current_a,
                "SensorCounterEcho": 0,
                "CycleCount": 0,
            },
            strict=False,
        )
    )
    return protect(data, counter, rig.codec.data_ids("VALVE_CMD"))  # type: ignore[arg-type]


def test_bad_commands_rejected_last_valid_holds_until_timeout(rig: Rig) -> None:
    good = rig.cmd(5e-4)
    assert rig.step()[0] == pytest.approx(5e-4, abs=2e-7)
    cid = rig.codec.can_id("VALVE_CMD")
    crc = bytearray(rig.codec.encode("VALVE_CMD", {"CurrentSetpoint": -5e-4, "Enable": 1}).data)
    crc[0] ^= 0xFF
    bad = [
        can.Message(arbitration_id=cid, data=bytes(crc), is_extended_id=False),  # wrong CRC
        good,  # repeated counter
        can.Message(arbitration_id=cid, data=_raw_cmd(rig, 1.5, 2), is_extended_id=False),
        can.Message(arbitration_id=cid, data=bytes(good.data[:7]), is_extended_id=False),  # DLC 7
    ]
    held = 0
    for i in range(TIMEOUT_PERIODS + 5):
        rig.peer.send(bad[i % len(bad)])
        applied, _ = rig.step()
        if applied != 0.0:
            assert applied == pytest.approx(5e-4, abs=2e-7)
            held += 1
    assert abs(held - (TIMEOUT_PERIODS - 1)) <= 1, held
    v = rig.verdicts
    # every bad frame rejected and counted (a resent frame is REPEATED or, once the implausible
    # frame moved the counter reference, WRONG_SEQUENCE)
    assert sum(n for verdict, n in v.items() if not verdict.usable) == TIMEOUT_PERIODS + 5
    assert v[Verdict.CRC_ERROR] >= 3 and v[Verdict.BAD_DLC] >= 3
    assert v[Verdict.REPEATED] >= 1 and v[Verdict.OUT_OF_RANGE] >= 1
    assert rig.proc.hold.accepted == 1


def test_enable_zero_applies_no_current(rig: Rig) -> None:
    rig.cmd(5e-4, enable=0)
    assert rig.step()[0] == 0.0


def test_fault_inject_only_when_enabled() -> None:
    for enabled in (False, True):
        r = Rig(f"inject-{enabled}", fault_inject=enabled)
        try:
            r.peer.send(r.codec.encode("FAULT_INJECT", {"FaultKind": 0, "Value": 0.5}))
            r.step()
            assert r.proc.emu.faults.k_loe == (0.5 if enabled else 1.0)
            r.peer.send(r.codec.encode("FAULT_INJECT", {"FaultKind": 2, "Value": 9.0}))
            r.step()  # k_dft 9 is out of range: rejected
            assert r.proc.emu.faults.k_dft == 1.0
            r.peer.send(r.codec.encode("FAULT_INJECT", {"FaultKind": 7, "Value": 0.0}))
            r.step()
            assert r.proc.emu.faults.k_loe == 1.0
            assert (r.proc.inject_applied, r.proc.inject_rejected) == ((2, 1) if enabled else (0, 0))
        finally:
            r.close()


def test_every_fault_inject_is_answered_with_its_status() -> None:
    """FAULT_INJECT_ACK echoes the kind and value and says APPLIED, OUT_OF_RANGE (k_loe 7),
    UNKNOWN_KIND, INVALID_FRAME (a bad CRC) or, with injection off, INJECTION_OFF."""
    names: Any = FrameCodec().message("FAULT_INJECT_ACK").get_signal_by_name("Status").choices or {}
    assert {int(k): str(v) for k, v in names.items()} == {s.value: s.name for s in InjectStatus}
    for enabled in (True, False):
        r = Rig(f"ack-{enabled}", fault_inject=enabled)
        try:
            sent = [
                r.codec.encode("FAULT_INJECT", {"FaultKind": 0, "Value": 0.5}),
                r.codec.encode("FAULT_INJECT", {"FaultKind": 0, "Value": 7.0}),
                r.codec.encode("FAULT_INJECT", {"FaultKind": 9, "Value": 1.0}),
            ]
            bad = r.codec.encode("FAULT_INJECT", {"FaultKind": 4, "Value": 1.0})
            sent.append(
                can.Message(
                    arbitration_id=bad.arbitration_id,
                    data=bytes([bad.data[0] ^ 1, *bad.data[1:]]),
                    is_extended_id=False,
                )
            )
            for msg in sent:
                r.peer.send(msg)
            r.proc.step_period()
            acks = [(a["FaultKind"], a["Status"], a["Value"]) for a in r.values_of("FAULT_INJECT_ACK")]
            if enabled:
                assert acks == [
                    (0, InjectStatus.APPLIED, 0.5),
                    (0, InjectStatus.OUT_OF_RANGE, 7.0),
                    (9, InjectStatus.UNKNOWN_KIND, 1.0),
                    (15, InjectStatus.INVALID_FRAME, 0.0),
                ]
                assert r.proc.emu.faults.k_loe == 0.5
            else:
                assert [a[1] for a in acks] == [InjectStatus.INJECTION_OFF] * 4
                assert r.proc.emu.faults.k_loe == 1.0
        finally:
            r.close()


def test_skipped_periods_advance_the_plant_without_frames(rig: Rig) -> None:
    """An emulator overrun that skipped 2 periods: the plant still advances 3 periods with the
    held command (the plant does not stop), one sensor pair goes out with its E2E counters 3
    on (2 samples lost), and the state equals an offline emulation stepped 3 times with that
    command."""
    rig.cmd(4e-4)
    rig.step()
    k0 = rig.proc.emu.k
    ref = PlantEmulation(load_params(), Scenario(name="t", duration_s=10.0))
    assert k0 == 1  # the command was applied at once: one period at 0.4 mA (as decoded)
    i_a = rig.proc.hold.current_a
    assert i_a == pytest.approx(4e-4, abs=2e-7)
    ref.measure()
    ref.advance(i_a)
    assert ref.plant.position_m == rig.proc.emu.plant.position_m
    sent = rig.proc.io.sent["SENSOR_POS"]
    rig.cmd(4e-4)
    rig.proc.step_period(skipped=2)
    assert rig.proc.emu.k == k0 + 3 and rig.proc.skipped_periods == 2
    assert rig.proc.io.sent["SENSOR_POS"] == sent + 1
    # the receiver sees the two skipped samples as lost: counters moved on by 3 (OK_SOME_LOST)
    got: dict[str, list[tuple[int, Verdict]]] = {}
    for m, d in rig.received():
        if d.name in ("SENSOR_POS", "SENSOR_AUX"):
            got.setdefault(d.name, []).append((m.data[1] & 0x0F, d.verdict))
    assert got == {
        "SENSOR_POS": [(3, Verdict.OK_SOME_LOST)],  # the first pair had counter 0
        "SENSOR_AUX": [(3, Verdict.OK_SOME_LOST)],
    }
    for _ in range(3):
        ref.measure()
        ref.advance(i_a)
    assert rig.proc.emu.plant.position_m == ref.plant.position_m != 0.0


def test_a_second_commander_centres_the_valve_until_one_is_left(rig: Rig) -> None:
    """A rogue node sends well-formed VALVE_CMDs (its own E2E counter, its own CycleCount) between
    the controller's: the emulator stops obeying either (0 A, CommandConflict 1), counts it, and
    obeys the controller again once the rogue has been quiet for a whole window."""
    rogue = FrameCodec()  # a second transmitter: its own TX counters
    for _ in range(5):  # the controller alone
        rig.cmd(2e-4)
        applied, aux = rig.step()
    assert applied == pytest.approx(2e-4, abs=1e-6) and aux["CommandConflict"] == 0
    seen = []
    for k in range(40):
        rig.cmd(2e-4)
        rig.peer.send(
            rogue.encode("VALVE_CMD", {"CurrentSetpoint": 0.5, "Enable": 1, "CycleCount": 40000 + k})
        )
        applied, aux = rig.step()
        seen.append((applied, aux["CommandConflict"]))
    assert all(a != 0.5 for a, _ in seen)  # the rogue's 0.5 A is never applied
    assert seen[-1] == (0.0, 1)
    assert rig.proc.commanders.conflicts == 1 and rig.proc.commanders.foreign >= 10
    for _ in range(120):  # the rogue is gone: one window later the controller rules again
        rig.cmd(3e-4)
        applied, aux = rig.step()
    assert applied == pytest.approx(3e-4, abs=1e-6) and aux["CommandConflict"] == 0
    assert rig.proc.summary()["command_conflicts"] == 1


def test_commander_check_rules() -> None:
    from firmware_sim.commanders import CommanderCheck

    chk = CommanderCheck(window=10, limit=3, max_ahead=100)
    assert all(chk.usable(c) for c in (0, 0, 0))  # a sender that never counts: no evidence
    assert chk.usable(1) and chk.usable(50) and chk.usable(51)  # in order, a catch-up of 49
    assert not chk.usable(40) and not chk.usable(51)  # a step back, a repeat
    assert not chk.conflict and chk.foreign == 2
    chk.rejected_sequence()  # an E2E counter out of sequence: the third foreign frame
    assert chk.conflict and chk.conflicts == 1
    for c in range(52, 62):  # a whole window in order
        assert chk.usable(c)
    assert not chk.conflict and chk.foreign == 3
    assert not chk.usable(62 + 101)  # a jump beyond max_ahead
    assert chk.usable(62 + 102) and chk.usable(62 + 103)  # ... by one commander: resync
    assert chk.foreign == 4 and not chk.conflict
    for c in range(200, 210):  # two senders alternating never resynchronize on each other
        chk.usable(c)
        chk.usable(c + 5000)
    assert chk.conflict
    wrap = CommanderCheck(window=10, limit=3, max_ahead=100)
    assert all(wrap.usable(c) for c in (65534, 65535, 0, 1))  # the 16-bit wrap is in order
