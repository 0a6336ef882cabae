"""The frame contract in code: DBC loaded once, AUTOSAR E2E profile 2, plausibility, verdicts."""

from .e2e import CounterCheck, E2EState, SampleCount, counter_steps
from .frames import Decoded, FrameCodec, Verdict

__all__ = ["CounterCheck", "Decoded", "E2EState", "FrameCodec", "SampleCount", "Verdict", "counter_steps"]
