"""The periodic status-frame schedule on its own (the loop's sending of it: test_daemon_loop)."""

from __future__ import annotations

from ehpss_hil.runtime.status_frames import FrameSchedule


def test_frame_schedule_keeps_due_frames_over_skipped_cycles() -> None:
    """The schedule alone: CTRL_STATUS on its multiples, CTRL_STATS/heartbeat one and two cycles
    after a coinciding CTRL_STATUS; a jump of the cycle count over a multiple (an overrun)
    still sends each frame once; a frame sent every cycle takes no slot."""
    sch = FrameSchedule(status_every=20, stats_every=100, heartbeat_every=100)
    sent = {c: sch.next(c, index_pending=True) for c in range(1, 201)}
    assert [c for c, d in sent.items() if d.status] == list(range(20, 201, 20))
    assert [c for c, d in sent.items() if d.stats] == [101]
    assert [c for c, d in sent.items() if d.heartbeat] == [102]
    assert all(sum(d) <= 1 for d in sent.values())
    assert not any(d.ctrl_index for c, d in sent.items() if d.status or d.stats or d.heartbeat)
    jump = sch.next(295, index_pending=False), sch.next(305, index_pending=False)
    assert jump[1].status and not jump[1].stats  # 300 passed while skipped: status first
    after = [sch.next(c, index_pending=False) for c in (306, 307, 308)]
    assert [a.stats for a in after] == [True, False, False]
    assert [a.heartbeat for a in after] == [False, True, False]
    every = FrameSchedule(status_every=20, stats_every=1, heartbeat_every=100)
    both = [every.next(c, index_pending=True) for c in range(1, 41)]
    # every cycle but CTRL_STATUS's, and the index frames still go out beside it
    assert [c for c, d in enumerate(both, 1) if not d.stats] == [20, 40]
    assert [c for c, d in enumerate(both, 1) if not d.ctrl_index] == [20, 40]


def test_the_dbc_names_every_failsafe_reason() -> None:
    """CTRL_STATUS's FailsafeReason VAL_ table is the enum, value for value (PDO_ERROR = 11)."""
    import cantools

    from ehpss_hil import DATA_DIR
    from ehpss_hil.protocol.failsafe import FailsafeReason

    db = cantools.database.load_file(str(DATA_DIR / "dbc" / "ehpss.dbc"))
    assert isinstance(db, cantools.database.can.Database)
    sig = db.get_message_by_name("CTRL_STATUS").get_signal_by_name("FailsafeReason")
    assert sig.choices is not None
    assert {int(k): str(v) for k, v in sig.choices.items()} == {r.value: r.name for r in FailsafeReason}
