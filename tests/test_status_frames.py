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
