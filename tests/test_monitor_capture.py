"""The monitor's triggered capture and the emulator's answers as the page reads them, with real
frames (the DBC through cantools) and explicit receive times (nothing is timed): a capture
armed on events fires on a fault event and writes the frames of its span as a candump log the
project's decoder reads and the rows of its span as CSV; a threshold capture fires on |e|; the
state keeps FAULT_INJECT_ACK answers and counts fail-safe trips."""

from __future__ import annotations

import csv
import math
from pathlib import Path

import can
import numpy as np
import pytest

from ehpss_hil.canlog import decode_log
from ehpss_hil.codec import FrameCodec
from ehpss_hil.errors import CaptureError
from ehpss_hil.monitor.capture import Capture, CaptureSpec
from ehpss_hil.monitor.state import ROW_FIELDS, STATE_FAULT, MonitorState, choice_names

TS = 1e-3  # s between frames
T0 = 1000.0  # s, the first frame's receive time


def _run(spec: CaptureSpec, tmp: Path, n: int = 3000, loe_at: int = 1500) -> tuple[Capture, MonitorState]:
    """Feed ``n`` ms of SENSOR_POS + PLANT_FAULTS (k_LOE 1 → 0.5 at ``loe_at``) into a state
    and an armed capture, as the listener does; write the capture when complete."""
    tx, rx = FrameCodec(), FrameCodec()
    st = MonitorState(choice_names(rx))
    cap = Capture(spec, tmp, 1)
    for k in range(n):
        t = T0 + k * TS
        msgs = [tx.encode("SENSOR_POS", {"Position": 1e-6 * (k % 500), "Spool": 0.0})]
        if k % 100 == 0 or k == loe_at:
            msgs.append(
                tx.encode("PLANT_FAULTS", {"KLoe": 0.5 if k >= loe_at else 1.0, "KQ": 1.0, "KDft": 1.0})
            )
        for m in msgs:
            seq = st.seq
            st.feed(rx.classify(m), m.dlc, t)
            cap.frame(m, t)
            if st.seq != seq and cap.row(dict(zip(ROW_FIELDS, st.rows[-1][1], strict=True))):
                cap.write([r for _, r in st.rows], st.status_t0())
        if cap.files:
            break
    return cap, st


def test_an_event_capture_writes_its_span_as_log_and_csv(tmp_path: Path) -> None:
    cap, st = _run(CaptureSpec("event", before_s=0.5, after_s=0.3), tmp_path)
    assert cap.state == "saved" and cap.reason == "k_loe_true 1 → 0.5"
    assert cap.fired_t_s == pytest.approx(T0 + 1.5, abs=0.011)  # the row after the change
    log, table = (tmp_path / f for f in cap.files)
    assert log.suffix == ".log" and table.suffix == ".csv"
    frames = decode_log(log, FrameCodec())
    t = frames["SENSOR_POS"]["t_s"]
    lo, hi = cap.fired_t_s - 0.5, cap.fired_t_s + 0.3
    assert t[0] >= lo - 1e-6 and t[-1] <= hi + 1e-6
    assert len(t) == pytest.approx(800, abs=2)  # every frame of the 0.8 s span, 1 per ms
    k = np.round((t - T0) / TS)
    assert np.allclose(frames["SENSOR_POS"]["Position"], 1e-6 * (k % 500), atol=1e-9)  # as sent
    assert set(np.round(frames["PLANT_FAULTS"]["KLoe"], 4)) == {1.0, 0.5}
    rows = list(csv.DictReader(table.open()))
    assert rows and [*rows[0]] == ["t_run_s", *ROW_FIELDS]
    t_rows = np.array([float(r["t_s"]) for r in rows])
    assert t_rows[0] >= lo and t_rows[-1] <= hi and len(rows) == pytest.approx(80, abs=2)  # 10-ms rows
    assert float(rows[0]["t_run_s"]) == pytest.approx(t_rows[0] - T0, abs=1e-6)  # run time: first frame
    assert {r["k_loe_true"] for r in rows} == {"1.0", "0.5"}
    assert cap.summary(st.status_t0())["fired_run_s"] == pytest.approx(1.5, abs=0.011)


def test_a_threshold_capture_fires_on_the_field(tmp_path: Path) -> None:
    cap, _ = _run(CaptureSpec("threshold", before_s=0.1, after_s=0.1, field="y_s_m", level=450e-6), tmp_path)
    assert cap.state == "saved" and cap.reason == "|y_s_m| > 0.00045"
    assert cap.fired_t_s == pytest.approx(T0 + 0.451, abs=0.011)  # y_s passes 450 µm at 451 ms


@pytest.mark.parametrize(
    ("spec", "words"),
    [
        ({"trigger": "later"}, "trigger"),
        ({"before_s": 11.0}, "before_s"),
        ({"after_s": math.nan}, "after_s"),
        ({"trigger": "threshold", "field": "state"}, "field"),
        ({"trigger": "threshold", "level": -1.0}, "level"),
    ],
)
def test_a_bad_capture_request_is_refused(spec: dict[str, object], words: str) -> None:
    with pytest.raises(CaptureError, match=words):
        CaptureSpec(**spec)  # type: ignore[arg-type]


def test_acks_and_trips_as_the_page_reads_them() -> None:
    tx, rx = FrameCodec(), FrameCodec()
    st = MonitorState(choice_names(rx))
    msgs: list[can.Message] = [
        tx.encode("FAULT_INJECT_ACK", {"FaultKind": 0, "Status": 1, "Value": 7.0}),
        tx.encode("FAULT_INJECT_ACK", {"FaultKind": 4, "Status": 0, "Value": 1.0}),
    ]
    for state in (2, 3, 3, 2, 3):
        msgs.append(tx.encode("CTRL_STATUS", {"State": state, "FailsafeReason": 1, "Mode": 3}))
    for i, m in enumerate(msgs):
        st.feed(rx.classify(m), m.dlc, T0 + i * 0.02)
    s = st.status()
    assert [(a["n"], a["kind"], a["status"], a["value"]) for a in s["inject_acks"]] == [
        (1, "k_loe", "OUT_OF_RANGE", 7.0),
        (2, "stuck", "APPLIED", 1.0),
    ]
    assert s["failsafe_trips"] == 2
    assert choice_names(rx)["State"][STATE_FAULT] == "FAULT"  # the constant is the DBC's code
    rows = st.rows_since(0)
    assert rows["state"][-1] == 3 and rows["failsafe_reason"][-1] == 1


def test_an_event_capture_fires_on_entering_the_fail_safe_or_the_fallback(tmp_path: Path) -> None:
    base = dict.fromkeys(ROW_FIELDS, 1.0) | {"state": 2.0, "fallback": 0.0, "stuck": 0.0}
    for change, reason in (({"state": 3.0}, "fail-safe (FAULT)"), ({"fallback": 1.0}, "nominal fallback")):
        cap = Capture(CaptureSpec("event", before_s=0.0, after_s=0.0), tmp_path, 1)
        assert not cap.row(base | {"t_s": T0}) and cap.state == "armed"
        assert cap.row(base | change | {"t_s": T0 + 0.01}) and cap.reason == reason
    # leaving them is no trigger
    cap = Capture(CaptureSpec("event", before_s=0.0, after_s=0.0), tmp_path, 2)
    cap.row(base | {"state": 3.0, "fallback": 1.0, "t_s": T0})
    assert not cap.row(base | {"t_s": T0 + 0.01}) and cap.state == "armed"
