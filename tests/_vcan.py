"""The SocketCAN tests' vcan0: why it cannot be used here (None: it can)."""

from __future__ import annotations

from pathlib import Path

from ehpss_hil.bus import af_can_available


def vcan_reason(channel: str = "vcan0") -> str | None:
    """None when ``channel`` is a SocketCAN interface here, else why not."""
    if not af_can_available():
        return "this kernel has no SocketCAN (socket(AF_CAN) fails): run via ../shared/tools/vcan-vm/run"
    if not Path(f"/sys/class/net/{channel}").exists():
        return f"{channel} does not exist (modprobe vcan; ip link add dev {channel} type vcan; up)"
    return None
