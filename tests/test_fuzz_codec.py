"""Reliability: fuzz the frame decoder with random IDs, DLCs and payloads (Hypothesis).

No exception may escape, every frame is counted under exactly one verdict, and a frame whose
data is acted on (OK / OK_SOME_LOST) is a known frame with a correct CRC and plausible values.
"""

from __future__ import annotations

import math

import can
from hypothesis import given, settings
from hypothesis import strategies as st

from ehpss_hil.codec import FrameCodec, Verdict
from ehpss_hil.codec.e2e import crc_ok, protect

_REF = FrameCodec()
_RX = FrameCodec()
_OUR_IDS = [_REF.can_id(n) for n in _REF.names]


def _frames() -> st.SearchStrategy[can.Message]:
    ids = st.one_of(st.sampled_from(_OUR_IDS), st.integers(0, 0x7FF), st.integers(0, 0x1FFFFFFF))
    return st.builds(
        lambda i, dlc, data, ext, rtr: can.Message(
            arbitration_id=i if (ext or i <= 0x7FF) else i & 0x7FF,
            data=data[:dlc],
            dlc=dlc,
            is_extended_id=ext,
            is_remote_frame=rtr,
            check=False,
        ),
        ids,
        st.integers(0, 8),
        st.binary(min_size=8, max_size=8),
        st.booleans(),
        st.booleans() | st.just(False),
    )


@settings(max_examples=1500, deadline=None)
@given(st.lists(_frames(), min_size=1, max_size=20))
def test_random_frames_never_escape_and_are_all_counted(frames: list[can.Message]) -> None:
    rx = _RX  # one codec for all examples: its sequence state carries over, which fuzzes it too
    before = sum(rx.counts.values())
    for f in frames:
        d = rx.classify(f)
        if d.verdict.usable:
            assert d.name is not None and d.values is not None
            assert f.arbitration_id in _OUR_IDS and not f.is_extended_id
            ids = rx.data_ids(d.name)
            assert ids is None or crc_ok(f.data, ids)
            assert rx.check_plausible(d.name, d.values) is None
    assert sum(rx.counts.values()) - before == len(frames)


@settings(max_examples=1500, deadline=None)
@given(
    st.sampled_from([n for n in _REF.names if _REF.data_ids(n) is not None]),
    st.binary(min_size=8, max_size=8),
    st.integers(0, 15),
)
def test_valid_crc_random_payload_is_plausible_or_out_of_range(
    name: str, payload: bytes, counter: int
) -> None:
    """A correctly protected frame with arbitrary content: decoded and range-checked, no crash."""
    rx = _RX
    rx.reset_rx()
    before = sum(rx.counts.values())
    ids = rx.data_ids(name)
    assert ids is not None
    data = protect(bytearray(payload), counter, ids)
    d = rx.classify(can.Message(arbitration_id=rx.can_id(name), data=data, is_extended_id=False))
    assert d.verdict in (Verdict.OK, Verdict.OUT_OF_RANGE)
    if d.verdict is Verdict.OK:
        assert d.values is not None
        for k, v in d.values.items():
            assert not (isinstance(v, float) and not math.isfinite(v)), k
    assert sum(rx.counts.values()) - before == 1
