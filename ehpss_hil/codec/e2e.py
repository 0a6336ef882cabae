"""AUTOSAR E2E profile 2 (CRC8H2F over bytes 1.. plus a per-counter DataID, 4-bit counter).

The CRC itself comes from ``cantools.autosar.end_to_end`` (crccheck's ``Crc8Autosar``), never
hand-written. Given an integer DataID cantools uses it as is, so the caller passes
``data_ids[counter]`` (DESIGN.md §6). The counter check is a simplified profile-2 receiver state
machine, one per frame ID.
"""

from __future__ import annotations

from enum import IntEnum

from cantools.autosar.end_to_end import apply_profile2_crc, check_profile2_crc


class E2EState(IntEnum):
    """Outcome of the counter check of one frame with a correct CRC."""

    OK = 0
    REPEATED = 1
    WRONG_SEQUENCE = 2
    OK_SOME_LOST = 3


def protect(payload: bytearray, counter: int, data_ids: tuple[int, ...]) -> bytes:
    """Write ``counter`` into the low nibble of byte 1 and the profile-2 CRC into byte 0."""
    payload[1] = (payload[1] & 0xF0) | (counter & 0x0F)
    out = apply_profile2_crc(bytes(payload), data_ids[counter & 0x0F])
    assert out is not None  # payload has >= 2 bytes
    return bytes(out)


def crc_ok(payload: bytes | bytearray, data_ids: tuple[int, ...]) -> bool:
    """True when byte 0 is the profile-2 CRC of the rest with the counter's DataID."""
    if len(payload) < 2:
        return False
    return bool(check_profile2_crc(bytes(payload), data_ids[payload[1] & 0x0F]))


class CounterCheck:
    """Profile-2 style sequence check for one frame ID.

    ``delta = (counter − last) mod 16``: 0 → REPEATED, 1 → OK, 2…max_delta → OK_SOME_LOST,
    otherwise WRONG_SEQUENCE. A WRONG_SEQUENCE frame does not move the reference (so a late,
    reordered frame can never make an older one acceptable again), but two consecutive frames in
    sequence after it resynchronize: the second is accepted as OK_SOME_LOST.
    """

    __slots__ = ("_candidate", "_last", "max_delta")

    def __init__(self, max_delta: int = 3) -> None:
        if not 1 <= max_delta <= 14:
            raise ValueError("max_delta must be in 1..14")
        self.max_delta = max_delta
        self._last: int | None = None
        self._candidate: int | None = None

    def reset(self) -> None:
        """Forget the reference (the next frame is accepted as OK)."""
        self._last = None
        self._candidate = None

    def check(self, counter: int) -> E2EState:
        """Classify ``counter`` and update the reference."""
        c = counter & 0x0F
        if self._last is None:
            self._last = c
            return E2EState.OK
        delta = (c - self._last) & 0x0F
        if delta == 0:
            return E2EState.REPEATED
        if delta <= self.max_delta:
            self._last = c
            self._candidate = None
            return E2EState.OK if delta == 1 else E2EState.OK_SOME_LOST
        if self._candidate is not None and c == ((self._candidate + 1) & 0x0F):
            self._last = c
            self._candidate = None
            return E2EState.OK_SOME_LOST
        self._candidate = c
        return E2EState.WRONG_SEQUENCE
