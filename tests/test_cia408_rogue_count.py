"""How the rogue trial counts the controller's cycles to its fail-safe (``rogue_cia408``): from
the controller's receipt of the rogue's first frame, on a candump log written here. A loaded
host may hold the rogue between its clock and its send while the controller keeps cycling."""

from __future__ import annotations

from pathlib import Path

import pytest

from ehpss_hil.reliability.rogue_cia408 import (
    VALVE,
    RogueCanopenResult,
    _failsafe_cycles,
    _receipt,
)

ACTIVE, DISABLED = "07000000", "01000000"


def _log(path: Path, lines: list[tuple[float, int, str]]) -> Path:
    path.write_text("".join(f"({t:.6f}) can0 {i:03X}#{d}\n" for t, i, d in lines))
    return path


def _controller_log(path: Path, received_s: float | None) -> Path:
    """The controller's RPDO (ACTIVE) each ms from t = 100.000 s, the rogue's NMT Stop received
    at ``received_s``, DISABLED on the next cycle after it (and its own NMT, stamped 0)."""
    lines: list[tuple[float, int, str]] = []
    t, react = 100.0, (received_s if received_s is not None else 100.0125)
    while t < react:
        lines += [(t, 0x200 + VALVE, ACTIVE), (t + 5e-5, 0x080, "")]
        t += 1e-3
    if received_s is not None:
        lines.append((received_s, 0x000, f"02{VALVE:02X}"))
    stop = f"02{VALVE:02X}"
    lines += [(t, 0x200 + VALVE, DISABLED), (0.0, 0x000, stop), (t + 1e-3, 0x200 + VALVE, DISABLED)]
    return _log(path, lines)


def test_cycles_count_from_the_controllers_receipt_not_the_rogues_clock(tmp_path: Path) -> None:
    # the rogue read its clock at 100.0002 s and its frame reached the controller 8 ms later
    log = _controller_log(tmp_path / "controller.log", received_s=100.0083)
    res = RogueCanopenResult("nmt-stop", sent=1, first_s=100.0002, delivered_s=100.0084)
    assert _receipt(log, res) == pytest.approx(100.0083, abs=1e-6)
    assert _failsafe_cycles(log, _receipt(log, res), b"") == 1
    assert _failsafe_cycles(log, res.first_s, b"") == 9  # the rogue's clock: 8 of them the host's


def test_a_frame_the_controller_sends_itself_counts_from_the_rogues_send(tmp_path: Path) -> None:
    log = _controller_log(tmp_path / "controller.log", received_s=None)
    res = RogueCanopenResult("sync", sent=500, first_s=100.0002, delivered_s=100.0101)
    assert _receipt(log, res) == res.delivered_s  # its own SYNCs are in the log too
    assert _failsafe_cycles(log, _receipt(log, res), b"") == 3


def test_a_rogue_frame_missing_from_the_log_counts_from_the_rogues_send(tmp_path: Path) -> None:
    log = _controller_log(tmp_path / "controller.log", received_s=None)
    res = RogueCanopenResult("nmt-stop", sent=1, first_s=100.0002, delivered_s=100.0063)
    assert _receipt(log, res) == res.delivered_s
    assert _failsafe_cycles(log, res.delivered_s, b"") == 7
