"""Reliability: frames with a known verdict and random ones through every decoder — the codec,
the controller loop (a realtime cycle per frame) and the emulator (a period per frame), on
python-can ``virtual`` buses: each frame counted once under its verdict, no rejected frame acted
on, no exception. Hypothesis drives the random frames through the two loops."""

from __future__ import annotations

from collections.abc import Iterator

import can
import pytest
from hypothesis import given, settings
from hypothesis import strategies as st

from ehpss_hil.codec import Decoded, FrameCodec, Verdict
from ehpss_hil.reliability.fuzz import (
    Receiver,
    codec_receiver,
    controller_receiver,
    emulator_receiver,
    fuzz_all,
)
from ehpss_hil.reliability.fuzzframes import FrameFuzzer, FuzzFrame

_IDS = [FrameCodec().can_id(n) for n in FrameCodec().names]


def test_every_receiver_counts_each_frame_under_its_verdict() -> None:
    codec, ctrl, emu = fuzz_all(1500, 1500, seed=11)
    for t in (codec, ctrl, emu):
        assert (t.crashes, t.mismatches, t.acted_on_bad) == (0, 0, 0), t.examples
        assert t.frames == 3000 and t.consumed == sum(t.by_verdict.values())
    assert codec.consumed == 3000 and all(n > 0 for n in codec.by_verdict.values())
    for t in (ctrl, emu):  # each receiver saw every kind of bad frame among its own IDs
        assert 0 < t.consumed < 3000
        for v in (
            "OK",
            "OK_SOME_LOST",
            "REPEATED",
            "WRONG_SEQUENCE",
            "CRC_ERROR",
            "BAD_DLC",
            "UNKNOWN_ID",
            "OUT_OF_RANGE",
        ):
            assert t.by_verdict[v] > 0, (t.target, v)


def test_fuzzer_is_seeded() -> None:
    a = FrameFuzzer(FrameCodec(), seed=5).crafted(200)
    b = FrameFuzzer(FrameCodec(), seed=5).crafted(200)
    assert [(f.msg.arbitration_id, bytes(f.msg.data), f.expected) for f in a] == [
        (f.msg.arbitration_id, bytes(f.msg.data), f.expected) for f in b
    ]


class _AcceptsDuplicates(FrameCodec):
    """A broken receiver: REPEATED frames are passed on as OK."""

    def classify(self, frame: can.Message) -> Decoded:
        d = super().classify(frame)
        if d.verdict is Verdict.REPEATED:
            self.counts[Verdict.REPEATED] -= 1
            self.counts[Verdict.OK] += 1
            return Decoded(Verdict.OK, d.name, {}, d.timestamp_s)
        return d


def test_the_harness_catches_a_receiver_that_accepts_duplicates() -> None:
    frames = FrameFuzzer(FrameCodec(), seed=3).crafted(1000)
    t = codec_receiver(_AcceptsDuplicates()).feed(frames)
    assert t.mismatches == sum(f.expected is Verdict.REPEATED for f in frames) > 0


@pytest.fixture(scope="module")
def loops() -> Iterator[tuple[Receiver, Receiver]]:
    ctrl, emu = controller_receiver(), emulator_receiver()
    yield ctrl, emu
    ctrl.close()
    emu.close()


def _frames() -> st.SearchStrategy[can.Message]:
    ids = st.one_of(st.sampled_from(_IDS), st.integers(0, 0x7FF), st.integers(0, 0x1FFFFFFF))
    return st.builds(
        lambda i, dlc, data, ext: can.Message(
            arbitration_id=i if (ext or i <= 0x7FF) else i & 0x7FF,
            data=data[:dlc],
            dlc=dlc,
            is_extended_id=ext,
            check=False,
        ),
        ids,
        st.integers(0, 8),
        st.binary(min_size=8, max_size=8),
        st.booleans(),
    )


@settings(max_examples=150, deadline=None)
@given(st.lists(_frames(), min_size=1, max_size=10))
def test_random_frames_through_both_loops(
    loops: tuple[Receiver, Receiver], frames: list[can.Message]
) -> None:
    for rx in loops:
        t = rx.feed([FuzzFrame(m, None) for m in frames])
        assert t.crashes == 0 and t.acted_on_bad == 0, t.examples
        assert t.frames == len(frames)
