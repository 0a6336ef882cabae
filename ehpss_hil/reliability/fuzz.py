"""Fuzz every decoder: :meth:`FrameCodec.classify`, the controller loop and the emulator.

The same seeded frames (:mod:`.fuzzframes`) go through three receivers, one frame at a time:

- ``codec``: :meth:`FrameCodec.classify` itself;
- ``controller``: a :class:`~ehpss_hil.runtime.controller_loop.ControllerLoop` (mode mmac) on a
  python-can ``virtual`` bus — each frame is sent on the bus, then one realtime cycle runs
  (:meth:`ControllerLoop.poll_cycle`: drain, E2E, watchdog, control step, VALVE_CMD);
- ``emulator``: an :class:`~firmware_sim.process.EmulatorProcess` (FAULT_INJECT accepted) on the
  same kind of bus — each frame, then one period (:meth:`EmulatorProcess.step_period`).

Per receiver: verdict counts (the receiver's own codec counters), frames whose verdict differs
from the crafted expectation, rejected frames that changed what the receiver acts on (controller:
its measurement; emulator: accepted commands and fault injections) and exceptions that escaped.
"""

from __future__ import annotations

import itertools
import logging
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from dataclasses import dataclass, field

import can

from ..codec import FrameCodec, Verdict
from ..control.registry import make_controller
from ..physics.load import load_params
from ..runtime.controller_loop import OWN_FRAMES as CTRL_OWN
from ..runtime.controller_loop import ControllerLoop, LoopOptions
from ..runtime.frameio import FrameIO
from ..scenario import Reference, Scenario
from .fuzzframes import FrameFuzzer, FuzzFrame

#: loggers that warn about every rejected frame / watchdog trip (thousands while fuzzing)
_NOISY = ("firmware_sim", "firmware_sim.command_hold", "ehpss_hil.controller")
_channels = itertools.count()


@dataclass
class FuzzTally:
    """What one receiver did with the fuzz frames."""

    target: str
    frames: int = 0
    #: frames the receiver classified (the others are not its to consume: other IDs, own echoes)
    consumed: int = 0
    by_verdict: dict[str, int] = field(default_factory=lambda: {v.name: 0 for v in Verdict})
    #: consumed crafted frames counted under another verdict than expected
    mismatches: int = 0
    #: rejected frames that changed the receiver's inputs
    acted_on_bad: int = 0
    crashes: int = 0
    examples: list[str] = field(default_factory=list)

    def note(self, what: str) -> None:
        """Keep a few examples of failures for the report."""
        if len(self.examples) < 5:
            self.examples.append(what)


def fuzz_all(n_crafted: int, n_random: int, seed: int = 1) -> list[FuzzTally]:
    """Crafted then random frames through every receiver (the same frames for each)."""
    fuzzer = FrameFuzzer(FrameCodec(), seed)
    frames = fuzzer.crafted(n_crafted) + fuzzer.random(n_random)
    tallies = []
    with _quiet():
        for make in (codec_receiver, controller_receiver, emulator_receiver):
            rx = make()
            try:
                tallies.append(rx.feed(frames))
            finally:
                rx.close()
    return tallies


@contextmanager
def _quiet() -> Iterator[None]:
    """Only errors from the receivers' loggers while fuzzing (each bad frame would warn)."""
    loggers = [logging.getLogger(n) for n in _NOISY]
    levels = [lg.level for lg in loggers]
    for lg in loggers:
        lg.setLevel(logging.CRITICAL)
    try:
        yield
    finally:
        for lg, lv in zip(loggers, levels, strict=True):
            lg.setLevel(lv)


def _delta(before: dict[Verdict, int], after: dict[Verdict, int]) -> Verdict | None:
    """The one verdict a receiver counted for one frame (None: not consumed)."""
    changed = [v for v in Verdict if after[v] != before[v]]
    if len(changed) > 1 or (changed and after[changed[0]] - before[changed[0]] != 1):
        raise AssertionError(f"one frame counted more than once: {changed}")
    return changed[0] if changed else None


class Receiver:
    """One receiver under fuzzing: its codec (whose counters say the verdict), one step per
    frame (deliver it and let the receiver run), and the inputs it acts on."""

    def __init__(
        self,
        name: str,
        codec: FrameCodec,
        step: Callable[[can.Message], object],
        inputs: Callable[[], tuple[object, ...]] = tuple,
        close: Callable[[], object] = lambda: None,
    ) -> None:
        self.name = name
        self.codec = codec
        self._step = step
        self._inputs = inputs
        self.close = close

    def feed(self, frames: list[FuzzFrame], tally: FuzzTally | None = None) -> FuzzTally:
        """One step per frame; verdicts from the codec's counters, exceptions counted."""
        t = tally if tally is not None else FuzzTally(self.name)
        for f in frames:
            before, seen = dict(self.codec.counts), self._inputs()
            try:
                self._step(f.msg)
            except Exception as exc:  # counted: this is what the fuzzing looks for
                t.crashes += 1
                t.note(f"{f.msg}: {exc!r}")
            got = _delta(before, self.codec.counts)
            t.frames += 1
            if got is None:
                continue
            t.consumed += 1
            t.by_verdict[got.name] += 1
            if f.expected is not None and got is not f.expected:
                t.mismatches += 1
                t.note(f"{f.msg}: expected {f.expected.name}, got {got.name}")
            if self._inputs() != seen and not got.usable:
                t.acted_on_bad += 1
                t.note(f"{f.msg}: {got.name} but acted on")
        return t


def codec_receiver(codec: FrameCodec | None = None) -> Receiver:
    """:meth:`FrameCodec.classify` itself."""
    c = codec if codec is not None else FrameCodec()
    return Receiver("codec", c, c.classify)


def _virtual_pair() -> tuple[can.BusABC, can.BusABC]:
    """Two python-can ``virtual`` buses on a fresh channel: (sender, receiver)."""
    ch = f"ehpss-fuzz-{next(_channels)}"
    return (
        can.Bus(interface="virtual", channel=ch, receive_own_messages=False),
        can.Bus(interface="virtual", channel=ch, receive_own_messages=False),
    )


def _on_bus(sender: can.BusABC, run: Callable[[], object]) -> Callable[[can.Message], None]:
    """Send the frame, run the receiver once, discard what it sent back."""

    def step(msg: can.Message) -> None:
        sender.send(msg)
        run()
        while sender.recv(0.0) is not None:
            pass

    return step


def controller_receiver() -> Receiver:
    """The controller loop (mmac, default watchdog) on a ``virtual`` bus, one realtime cycle
    (:meth:`ControllerLoop.poll_cycle`) per frame; inputs: its measurement."""
    sender, bus = _virtual_pair()
    io = FrameIO(bus, FrameCodec(), CTRL_OWN)
    ref = Reference()
    ctrl = make_controller("mmac", load_params(), 1e-3, None, ref)
    loop = ControllerLoop(ctrl, io, ref, LoopOptions())  # type: ignore[arg-type]
    loop.start()
    m = loop.meas

    def close() -> None:
        sender.shutdown()
        bus.shutdown()

    return Receiver(
        "controller",
        io.codec,
        _on_bus(sender, loop.poll_cycle),
        lambda: (m.position_m, m.spool_m, m.coil_current_a, m.load_pressure_pa),
        close,
    )


def emulator_receiver() -> Receiver:
    """The emulator (FAULT_INJECT accepted) on a ``virtual`` bus, one realtime period
    (:meth:`EmulatorProcess.step_period`) per frame; inputs: accepted commands and injections."""
    from firmware_sim.process import OWN_FRAMES, EmulatorOptions, EmulatorProcess

    from ..emulation import PlantEmulation

    sender, bus = _virtual_pair()
    io = FrameIO(bus, FrameCodec(), OWN_FRAMES)
    emu = PlantEmulation(load_params(), Scenario(name="fuzz", duration_s=3600.0))
    proc = EmulatorProcess(emu, io, EmulatorOptions(fault_inject=True))

    def close() -> None:
        sender.shutdown()
        bus.shutdown()

    return Receiver(
        "emulator",
        io.codec,
        _on_bus(sender, proc.step_period),
        lambda: (proc.hold.accepted, proc.inject_applied),
        close,
    )
