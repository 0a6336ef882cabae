"""A device-under-test bus and a test peer on one python-can ``virtual`` channel, for the
in-process rigs of the daemon loop and the emulator (periods are counted, nothing is timed)."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import can

from ehpss_hil.codec import FrameCodec
from ehpss_hil.codec.frames import Decoded


class VirtualPair:
    """``bus`` for the process under test, ``peer`` for the test, ``rx`` the peer's decoder."""

    def __init__(self, channel: str) -> None:
        self.bus = can.Bus(interface="virtual", channel=channel)
        self.peer = can.Bus(interface="virtual", channel=channel)
        self.rx = FrameCodec()

    def received(self) -> Iterator[tuple[can.Message, Decoded]]:
        """Every frame pending at the peer (without waiting), with its verdict and values."""
        while (m := self.peer.recv(0.0)) is not None:
            yield m, self.rx.classify(m)

    def newest(self) -> dict[str, dict[str, Any]]:
        """The values of the newest valid frame of each name pending at the peer."""
        return {d.name: d.values for _, d in self.received() if d.name is not None and d.values is not None}

    def values_of(self, name: str) -> list[dict[str, Any]]:
        """The values of every valid ``name`` frame pending at the peer, in order."""
        return [d.values for _, d in self.received() if d.name == name and d.values is not None]

    def close(self) -> None:
        self.bus.shutdown()
        self.peer.shutdown()
