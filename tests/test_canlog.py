"""candump -L writer/reader: golden format, python-can and ``cantools decode`` round trips,
no loss at 3 frames/ms, rotation, overflow accounting, idempotent close."""

from __future__ import annotations

import json
import re
import subprocess
import sys
import threading
from pathlib import Path

import can
import pytest

from ehpss_hil import DEFAULT_DBC
from ehpss_hil.canlog import CandumpLogger, decode_log, log_files, read_log, read_sidecar
from ehpss_hil.codec import FrameCodec

LINE_RE = re.compile(
    r"^\(\d{10}\.\d{6}\) \S+ ([0-9A-F]{3}|[0-9A-F]{8})#(R[0-8]?|#[0-9A-F]"
    r"(?:[0-9A-F]{2})*|(?:[0-9A-F]{2})*)\n$"
)
CANTOOLS = Path(sys.executable).with_name("cantools")
T0 = 1_700_000_000.0


def sample_frames(codec: FrameCodec, n_cycles: int = 40) -> list[can.Message]:
    """Every DBC frame kind with varying values, timestamps 1 ms apart (s)."""
    out: list[can.Message] = []
    for k in range(n_cycles):
        t = T0 + k * 1e-3
        out.append(
            codec.encode(
                "SENSOR_POS", {"Position": 1e-4 * k - 2e-3, "Spool": -3e-6 * (k % 100)}, timestamp_s=t
            )
        )
        out.append(
            codec.encode(
                "SENSOR_AUX",
                {"LoadPressure": 1e4 * k, "CoilCurrent": -0.001 * (k % 100), "ValveEnabled": 1},
                timestamp_s=t,
            )
        )
        out.append(
            codec.encode(
                "VALVE_CMD",
                {
                    "CurrentSetpoint": 0.002 * (k % 100),
                    "Enable": 1,
                    "CycleCount": k,
                    "SensorCounterEcho": k % 16,
                },
                timestamp_s=t + 1e-4,
            )
        )
        out.append(
            codec.encode(
                "PLANT_TRUTH", {"Position": 1e-4 * k, "SpoolActual": 1e-6 * (k % 100)}, timestamp_s=t
            )
        )
        if k % 10 == 0:
            slot = (k // 10) % 7
            out.append(
                codec.encode(
                    "CTRL_STATUS",
                    {"State": 2, "Mode": 3, "KLoeHat": 0.5, "KDftHat": 1.0, "ActiveSpoolModel": 1},
                    timestamp_s=t,
                )
            )
            out.append(
                codec.encode(
                    "CTRL_INDEX",
                    {"ModelSlot": slot, f"J_{slot}": 0.25 * k, f"Theta_{slot}": 0.5},
                    timestamp_s=t,
                )
            )
            out.append(codec.encode("PLANT_FAULTS", {"KLoe": 0.8, "KQ": 1.0, "KDft": 1.0}, timestamp_s=t))
            out.append(codec.encode("HEARTBEAT_CTRL", {"NmtState": 5}, timestamp_s=t))
    return out


def write_log(path: Path, frames: list[can.Message], **kw: object) -> CandumpLogger:
    lg = CandumpLogger(path, iface="vcan0", **kw)  # type: ignore[arg-type]
    for m in frames:
        lg.log(m)
    lg.close()
    return lg


def test_golden_lines(tmp_path: Path) -> None:
    """Byte-exact candump -L lines for standard, extended, remote and FD frames."""
    msgs = [
        can.Message(
            timestamp=1.5, arbitration_id=0x110, is_extended_id=False, data=bytes.fromhex("8700000000881300")
        ),
        can.Message(
            timestamp=1700000000.000001, arbitration_id=0x1ABCDEF, is_extended_id=True, data=b"\x01\xab"
        ),
        can.Message(timestamp=2.0, arbitration_id=0x123, is_extended_id=False, is_remote_frame=True, dlc=8),
        can.Message(
            timestamp=3.25,
            arbitration_id=0x7FF,
            is_extended_id=False,
            is_fd=True,
            bitrate_switch=True,
            data=bytes(range(12)),
        ),
        can.Message(timestamp=4.0, arbitration_id=0x001, is_extended_id=False, data=b""),
    ]
    write_log(tmp_path / "g.log", msgs)
    assert (tmp_path / "g.log").read_text() == (
        "(0000000001.500000) vcan0 110#8700000000881300\n"
        "(1700000000.000001) vcan0 01ABCDEF#01AB\n"
        "(0000000002.000000) vcan0 123#R8\n"
        "(0000000003.250000) vcan0 7FF##1000102030405060708090A0B\n"
        "(0000000004.000000) vcan0 001#\n"
    )
    back = list(read_log(tmp_path / "g.log"))
    for a, b in zip(msgs, back, strict=True):
        assert a.equals(b, timestamp_delta=1e-6, check_channel=False, check_direction=False)


def test_python_can_round_trip(tmp_path: Path) -> None:
    codec = FrameCodec()
    frames = sample_frames(codec)
    write_log(tmp_path / "run.log", frames)
    with can.CanutilsLogReader(tmp_path / "run.log") as reader:
        back = list(reader)
    assert len(back) == len(frames)
    for a, b in zip(frames, back, strict=True):
        assert (b.arbitration_id, bytes(b.data), b.dlc, b.is_extended_id) == (
            a.arbitration_id,
            bytes(a.data),
            a.dlc,
            a.is_extended_id,
        )
        assert b.timestamp == pytest.approx(a.timestamp, abs=1e-6)
        assert b.channel == "vcan0"


def _parse_cantools_line(line: str) -> tuple[str, dict[str, float]]:
    """``(...) vcan0 110#.. :: SENSOR_POS(CRC: 1, Position: 0.001 m)`` -> name, values."""
    m = re.search(r":: (\w+)\((.*)\)$", line)
    assert m, line
    values = {}
    for part in m.group(2).split(", "):
        key, val = part.split(": ")
        values[key] = float(val.split()[0])
    return m.group(1), values


def test_cantools_decode_cli_frame_for_frame(tmp_path: Path) -> None:
    """The real ``cantools decode`` CLI on our DBC decodes every line to our codec's values."""
    codec = FrameCodec()
    frames = sample_frames(codec)
    log = tmp_path / "run.log"
    write_log(log, frames)
    res = subprocess.run(
        [str(CANTOOLS), "decode", "--single-line", "--no-decode-choices", str(DEFAULT_DBC)],
        stdin=log.open(),
        capture_output=True,
        text=True,
        check=True,
        timeout=60,
    )
    lines = res.stdout.splitlines()
    assert len(lines) == len(frames)
    rx = FrameCodec()
    for line, frame, text in zip(lines, frames, log.read_text().splitlines(), strict=True):
        assert line.startswith(text + " :: ")
        name, values = _parse_cantools_line(line)
        ours = rx.classify(frame)
        assert ours.verdict.usable and ours.name == name
        assert values.keys() == ours.values.keys()  # type: ignore[union-attr]
        for k, v in values.items():
            assert v == pytest.approx(ours.values[k], rel=1e-9, abs=1e-12)  # type: ignore[index]


def test_decode_log_arrays(tmp_path: Path) -> None:
    codec = FrameCodec()
    write_log(tmp_path / "run.log", sample_frames(codec, 40))
    data = decode_log(tmp_path / "run.log", FrameCodec())
    assert len(data["SENSOR_POS"]["t_s"]) == 40
    assert data["SENSOR_POS"]["Position"][5] == pytest.approx(1e-4 * 5 - 2e-3, abs=1e-7)
    idx = data["CTRL_INDEX"]
    assert list(idx["ModelSlot"]) == [0, 1, 2, 3]
    assert idx["J_1"][1] == pytest.approx(2.5)


def test_three_frames_per_ms_for_60_s_none_lost_with_rotation(tmp_path: Path) -> None:
    """180 000 frames (60 s of 3 frames/ms timestamps) logged as fast as possible: 0 lost,
    rotated files each standalone-readable, whole lines only, order kept."""
    codec = FrameCodec()
    base = [codec.encode(n, {}) for n in ("SENSOR_POS", "SENSOR_AUX", "VALVE_CMD")]
    n_ms = 60_000
    log = tmp_path / "run.log"
    lg = CandumpLogger(log, iface="can0", max_bytes=1_000_000, backups=50)
    for k in range(n_ms):
        for m in base:
            m.timestamp = T0 + k * 1e-3
            lg.log(m)
    summary = lg.close()
    sent = 3 * n_ms
    assert (summary.dropped, summary.written, lg.written) == (0, sent, sent)
    files = log_files(log)
    assert len(files) > 5 and [str(f) for f in files] == summary.files
    total = 0
    last_t = 0.0
    for f in files:
        raw = f.read_bytes()
        assert len(raw) <= 1_000_000 and raw.endswith(b"\n")
        with can.CanutilsLogReader(f) as reader:  # each file alone
            msgs = list(reader)
        assert msgs[0].timestamp >= last_t
        last_t = msgs[-1].timestamp
        total += len(msgs)
    assert total == sent
    side = read_sidecar(log)
    assert side is not None and side["status"] == "closed"
    assert side["counts"] == {"written": sent, "dropped": 0, "discarded_by_rotation": 0}
    assert sum(f["lines"] for f in side["files"]) == sent
    assert [f["name"] for f in side["files"]] == [f.name for f in files]


def test_rotation_discards_are_counted(tmp_path: Path) -> None:
    codec = FrameCodec()
    log = tmp_path / "run.log"
    frames = sample_frames(codec, 400)
    lg = write_log(log, frames, max_bytes=8192, backups=2)
    files = log_files(log)
    assert len(files) == 3
    on_disk = 0
    for f in files:
        for line in f.read_text().splitlines(keepends=True):
            assert LINE_RE.match(line), line
            on_disk += 1
    side = read_sidecar(log)
    assert side is not None
    assert side["counts"]["discarded_by_rotation"] > 0
    assert on_disk + side["counts"]["discarded_by_rotation"] == len(frames) == lg.written


def test_overflow_is_counted_never_blocks(tmp_path: Path) -> None:
    codec = FrameCodec()
    frames = sample_frames(codec, 600)
    gate = threading.Event()
    lg = CandumpLogger(tmp_path / "run.log", queue_lines=1000)
    orig = lg._write_batch

    def held(batch):  # type: ignore[no-untyped-def]
        gate.wait()
        orig(batch)

    lg._write_batch = held  # type: ignore[method-assign]
    for m in frames:
        lg.log(m)  # returns at once even though the writer is stuck
    dropped_while_stuck = lg.dropped
    gate.set()
    summary = lg.close()
    assert dropped_while_stuck >= len(frames) - 1000 - 64 > 0
    assert summary.written + summary.dropped == len(frames)
    assert len((tmp_path / "run.log").read_text().splitlines()) == summary.written
    side = json.loads((tmp_path / "run.log.json").read_text())
    assert side["counts"]["dropped"] == summary.dropped


def test_close_is_idempotent_and_late_frames_counted(tmp_path: Path) -> None:
    codec = FrameCodec()
    lg = CandumpLogger(tmp_path / "run.log", sidecar={"scenario": {"name": "x"}, "dbc": str(DEFAULT_DBC)})
    lg.log(codec.encode("SENSOR_POS", {}, timestamp_s=T0))
    s1 = lg.close()
    s2 = lg.close()
    assert s1 is s2 and s1.written == 1
    lg.log(codec.encode("SENSOR_POS", {}, timestamp_s=T0))
    assert lg.dropped == 1
    side = read_sidecar(tmp_path / "run.log")
    assert side is not None
    assert side["scenario"] == {"name": "x"} and len(side["dbc"]["sha256"]) == 64
    assert set(side["versions"]) >= {"ehpss-hil", "python-can", "cantools"}


def test_stale_backups_of_an_earlier_run_are_removed(tmp_path: Path) -> None:
    """The rotated files of an earlier log of ours (its sidecar lists them) go when the log is
    opened again; a numbered file the sidecar does not list is the user's and stays."""
    log = tmp_path / "run.log"
    write_log(log, sample_frames(FrameCodec(), 40), max_bytes=1000, backups=3)
    assert [p.name for p in log_files(log)] == ["run.log.3", "run.log.2", "run.log.1", "run.log"]
    (tmp_path / "run.log.2024").write_text("the user's\n")
    write_log(log, [])
    assert sorted(p.name for p in tmp_path.iterdir()) == ["run.log", "run.log.2024", "run.log.json"]
    assert (tmp_path / "run.log.2024").read_text() == "the user's\n"


def test_kick_from_a_loop_keeps_every_frame(tmp_path: Path) -> None:
    """A loop logs a few frames per cycle and kicks the writer when it goes idle: every frame is
    written, in order; a kick with little queued does nothing; a kick after close is harmless."""
    frames = sample_frames(FrameCodec(), 300)
    lg = CandumpLogger(tmp_path / "k.log", iface="vcan0")
    lg.log(frames[0])
    lg.kick()
    assert lg._kick.locked()  # fewer than _KICK_LINES queued: the writer is not woken
    for i, m in enumerate(frames[1:]):
        lg.log(m)
        if i % 5 == 4:
            lg.kick()
    s = lg.close()
    lg.kick()
    assert s.written == len(frames) and s.dropped == 0
    back = list(read_log(tmp_path / "k.log"))
    assert [(m.arbitration_id, bytes(m.data)) for m in back] == [
        (m.arbitration_id, bytes(m.data)) for m in frames
    ]
