"""Worst-case CAN frame lengths and the bus load of the shipped profiles (computed figures)."""

from __future__ import annotations

from pathlib import Path

import pytest

from ehpss_hil.bench.bus import profile_frames
from ehpss_hil.protocol.busload import frame_bits, load

ROOT = Path(__file__).resolve().parent.parent


@pytest.mark.parametrize(
    ("n", "extended", "bits"),
    [(0, False, 55), (8, False, 135), (6, False, 115), (0, True, 80), (8, True, 160)],
)
def test_worst_case_frame_bits(n: int, extended: bool, bits: int) -> None:
    assert frame_bits(n, extended) == bits


def test_frame_bits_refuses_can_fd_lengths() -> None:
    with pytest.raises(ValueError):
        frame_bits(9, False)


def test_profile_loads() -> None:
    native = profile_frames(str(ROOT / "configs" / "controller.yaml"), 1000.0, "mmac")
    vendor = profile_frames(str(ROOT / "configs" / "controller-vendor.yaml"), 1000.0, "mmac")
    # three 8-byte valve frames per ms, then 50 Hz status + 9 index frames, 10 Hz stats, 2 heartbeats
    assert [f.data_bytes for f in native[:3]] == [8, 8, 8] and [f.data_bytes for f in vendor[:3]] == [8, 8, 6]
    others = 135 * (50 + 450 + 10) + 2 * 10 * frame_bits(1, False)
    assert load(native, 1e6) == pytest.approx((3 * 135 * 1000 + others) / 1e6)
    assert load(vendor, 1e6) == pytest.approx((2 * 135 * 1000 + 115 * 1000 + others) / 1e6)


def test_cia408_profile_counts_the_pdos_sync_device_frame_and_node_heartbeats() -> None:
    """Per ms the encoder TPDO, the valve TPDO and RPDO (4 bytes each) and the master's SYNC (no
    data); CTRL_DEVICE beside the 50-Hz CTRL_STATUS; the two nodes' 1-byte heartbeats at 10 Hz
    (heartbeat_time_ms 100) instead of the emulator's."""
    frames = profile_frames(str(ROOT / "configs" / "controller-cia408.yaml"), 1000.0, "mmac")
    names = [f.name for f in frames]
    assert names[:4] == ["SENSOR_POS", "SENSOR_AUX", "VALVE_CMD", "SYNC"]
    assert [f.data_bytes for f in frames[:4]] == [4, 4, 4, 0]
    assert "CTRL_DEVICE" in names and "HEARTBEAT_EMU" not in names
    assert names.count("node heartbeat") == 2
    others = 135 * (50 + 450 + 10 + 50) + 10 * frame_bits(1, False) + 2 * 10 * frame_bits(1, False)
    cyclic = 3 * frame_bits(4, False) + frame_bits(0, False)
    assert load(frames, 1e6) == pytest.approx((cyclic * 1000 + others) / 1e6)
