"""AUTOSAR E2E profile 2 (CRC8H2F over bytes 1.. plus a per-counter DataID, 4-bit counter).

The CRC is crccheck's ``Crc8Autosar`` (CRC8H2F), the one ``cantools.autosar.end_to_end``
computes; given an integer DataID cantools uses it as is, so the caller passes
``data_ids[counter]`` (docs/design.md §7). crccheck runs it bit by bit (≈ 6 µs per 8-byte frame);
here the same CRC runs byte-wise on a 256-entry table that crccheck itself fills at import (one
byte from register 0 per entry; the polynomial appears nowhere in this file), ≈ 0.3 µs.
``tests/test_codec_layout.py`` checks it against ``cantools.autosar.end_to_end`` for every DataID
and random payloads, and the import checks crccheck's own check value. The counter check is a
simplified profile-2 receiver state machine, one per frame ID.
"""

from __future__ import annotations

from enum import IntEnum

from crccheck.crc import Crc8Autosar


def _crc_table() -> tuple[int, ...]:
    """Register after one byte from register 0, without the final XOR (crccheck's own step).
    Byte-wise table lookup equals crccheck's bitwise loop for a non-reflected 8-bit CRC."""
    if Crc8Autosar.width() != 8 or Crc8Autosar.reflect_input() or Crc8Autosar.reflect_output():
        raise ImportError("Crc8Autosar is no longer a non-reflected 8-bit CRC")
    return tuple(Crc8Autosar(0).process(bytes([b])).value() for b in range(256))


_TABLE = _crc_table()
_INIT = Crc8Autosar.initvalue()
_XOR_OUT = Crc8Autosar.xor_output()


def _crc8(data: bytes | bytearray) -> int:
    t = _TABLE
    crc = _INIT
    for b in data:
        crc = t[crc ^ b]
    return crc ^ _XOR_OUT


if _crc8(Crc8Autosar.check_data()) != Crc8Autosar.check_result():
    raise ImportError("CRC table disagrees with crccheck's Crc8Autosar check value")


def profile2_crc(payload: bytes | bytearray, data_id: int) -> int:
    """The profile-2 CRC of ``payload[1:]`` followed by ``data_id`` (0..255): what
    ``cantools.autosar.end_to_end.compute_profile2_crc(payload, data_id)`` returns."""
    t = _TABLE
    crc = _INIT
    for b in payload[1:]:
        crc = t[crc ^ b]
    return t[crc ^ data_id] ^ _XOR_OUT


class E2EState(IntEnum):
    """Outcome of the counter check of one frame with a correct CRC."""

    OK = 0
    REPEATED = 1
    WRONG_SEQUENCE = 2
    OK_SOME_LOST = 3


def protect(payload: bytearray, counter: int, data_ids: tuple[int, ...]) -> bytes:
    """Write ``counter`` into the low nibble of byte 1 and the profile-2 CRC into byte 0 of
    ``payload`` (in place) and return the protected bytes."""
    c = counter & 0x0F
    payload[1] = (payload[1] & 0xF0) | c
    payload[0] = profile2_crc(payload, data_ids[c])  # over bytes 1..: byte 0 does not count
    return bytes(payload)


def crc_ok(payload: bytes | bytearray, data_ids: tuple[int, ...]) -> bool:
    """True when byte 0 is the profile-2 CRC of the rest with the counter's DataID."""
    if len(payload) < 2:
        return False
    return payload[0] == profile2_crc(payload, data_ids[payload[1] & 0x0F])


def counter_steps(counter: int, previous: int) -> int:
    """Samples from the frame with 4-bit counter ``previous`` to the one with ``counter``:
    1…16 (a whole wrap, 0 apart, counts as 16; more than 16 cannot be told from the counter)."""
    return ((counter - previous - 1) & 0x0F) + 1


class SampleCount:
    """Sensor samples between the SENSOR_POS frames a controller steps on, from their E2E
    counters (:func:`counter_steps`; the daemon and ``replay`` count alike): 0 for the first one
    after a (re)start, when there is nothing to count from."""

    __slots__ = ("last",)

    def __init__(self) -> None:
        self.last: int | None = None

    def reset(self) -> None:
        """Nothing stepped on yet (start, a controller reset)."""
        self.last = None

    def take(self, counter: int) -> int:
        """The frame with ``counter`` is stepped on: samples since the previous one (0: first)."""
        last, self.last = self.last, counter
        return 0 if last is None else counter_steps(counter, last)


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
