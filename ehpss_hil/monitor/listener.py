"""The monitor's bus thread: receive, classify with the DBC, fold into a :class:`MonitorState`.

One thread reads and decodes every frame (the web server's event loop never touches the bus);
the state is shared under :attr:`BusListener.lock`. With ``netns`` the thread first enters that
network namespace (a run's private bus) and opens the bus there, while the web server's socket,
opened by another thread, stays on the host's loopback. The monitor transmits nothing, except a
FAULT_INJECT frame when :meth:`BusListener.inject` is called (the page's buttons, only with
``--allow-inject``). A triggered capture (:mod:`.capture`), when armed, is fed here too and
written from this thread once complete.
"""

from __future__ import annotations

import math
import threading
import time
from collections.abc import Callable
from pathlib import Path
from typing import Any

import can

from ..bus.netns import enter_netns
from ..codec import FrameCodec
from ..errors import BusUnavailableError, CaptureError, FrameError, InjectError
from .capture import Capture, CaptureSpec
from .state import ROW_FIELDS, MonitorState

#: how long :meth:`BusListener.start` waits for the bus to open (s)
OPEN_TIMEOUT_S = 10.0
#: longest blocking receive, so a stop is seen this quickly (s)
RECV_TIMEOUT_S = 0.1


class BusListener:
    """The receive thread of one bus (see the module docstring)."""

    def __init__(
        self,
        open_bus: Callable[[], can.BusABC],
        codec: FrameCodec,
        state: MonitorState,
        tx_codec: FrameCodec | None = None,
        netns: str | None = None,
        allow_inject: bool = False,
        capture_dir: Path | None = None,
    ) -> None:
        self._open_bus = open_bus
        self.codec = codec
        self.state = state
        self._tx = tx_codec
        self.netns = netns
        self.allow_inject = allow_inject
        self.lock = threading.Lock()
        self._send_lock = threading.Lock()
        self._stop = threading.Event()
        self._opened = threading.Event()
        self._error: BaseException | None = None
        self._bus: can.BusABC | None = None
        self._thread = threading.Thread(target=self._run, name="monitor-bus", daemon=True)
        self.injected: list[tuple[str, float]] = []
        #: where triggered captures are written (None: captures off)
        self.capture_dir = capture_dir
        #: the armed (or last) capture; guarded by :attr:`lock`
        self.capture: Capture | None = None
        self._captures = 0
        kinds: dict[int, Any] = codec.message("FAULT_INJECT").get_signal_by_name("FaultKind").choices or {}
        #: fault kind name (DBC FaultKind value table) → code
        self.kinds = {str(name): int(code) for code, name in kinds.items()}

    def start(self) -> None:
        """Start the thread and wait until the bus is open; raises what opening it raised."""
        self._thread.start()
        if not self._opened.wait(OPEN_TIMEOUT_S):
            raise BusUnavailableError(f"the bus did not open within {OPEN_TIMEOUT_S:g} s")
        if self._error is not None:
            raise self._error

    def stop(self) -> None:
        """Stop receiving and close the bus."""
        self._stop.set()
        if self._thread.is_alive():
            self._thread.join(timeout=5.0)

    @property
    def alive(self) -> bool:
        """True while the receive thread runs."""
        return self._thread.is_alive()

    def _run(self) -> None:
        try:
            if self.netns:
                try:
                    enter_netns(self.netns)
                except OSError as exc:
                    raise BusUnavailableError(
                        f"cannot enter the network namespace {self.netns}: {exc}"
                    ) from exc
            self._bus = self._open_bus()
        except BaseException as exc:
            self._error = exc
            self._opened.set()
            return
        self._opened.set()
        try:
            self._receive(self._bus)
        except (OSError, can.CanError) as exc:  # the bus went away: the command reports it
            self._error = BusUnavailableError(f"the bus failed while listening: {exc}")
        finally:
            self._bus.shutdown()

    @property
    def error(self) -> BaseException | None:
        """What ended the receive thread other than :meth:`stop` (None: nothing)."""
        return self._error

    def _receive(self, bus: can.BusABC) -> None:
        classify, feed, lock, state = self.codec.classify, self.state.feed, self.lock, self.state
        while not self._stop.is_set():
            msg = bus.recv(timeout=RECV_TIMEOUT_S)
            if msg is None:
                continue
            d = classify(msg)
            now = time.time()
            done, rows = False, []
            with lock:
                seq = state.seq
                feed(d, msg.dlc, now)
                cap = self.capture
                if cap is not None and not cap.files:
                    cap.frame(msg, now)
                    if state.seq != seq:
                        done = cap.row(dict(zip(ROW_FIELDS, state.rows[-1][1], strict=True)))
                    if done:
                        rows, t0 = [r for _, r in state.rows], state.status_t0()
            if done and cap is not None:
                try:
                    cap.write(rows, t0)
                except OSError as exc:  # a full disk: the capture says so, the monitor goes on
                    cap.reason += f" (not saved: {exc.strerror or exc})"
                    cap.files = ["(not saved)"]

    def arm(self, spec: CaptureSpec) -> dict[str, object]:
        """Arm a triggered capture (replacing one not yet triggered); returns its summary.
        Raises :class:`CaptureError` when captures are off or one is being collected."""
        if self.capture_dir is None:
            raise CaptureError("captures are off (start the monitor with --capture-dir)")
        with self.lock:
            if self.capture is not None and self.capture.state == "triggered":
                raise CaptureError("a capture is being collected: wait until it is saved")
            self._captures += 1
            self.capture = Capture(spec, self.capture_dir, self._captures)
            return self.capture.summary(self.state.status_t0())

    def inject(self, kind: str, value: float) -> str:
        """Send one FAULT_INJECT frame (``kind``: a DBC FaultKind name, ``value`` in its unit);
        returns what was sent. Raises :class:`InjectError` when refused."""
        if not self.allow_inject or self._tx is None:
            raise InjectError("fault injection is off (start the monitor with --allow-inject)")
        code = self.kinds.get(kind)
        if code is None:
            raise InjectError(f"unknown fault kind {kind!r} (one of {', '.join(self.kinds)})")
        if not math.isfinite(value):
            raise InjectError(f"{kind}: value must be a finite number, got {value!r}")
        bus = self._bus
        if bus is None:
            raise InjectError("the bus is not open")
        with self._send_lock:
            try:
                msg = self._tx.encode("FAULT_INJECT", {"FaultKind": code, "Value": value})
                bus.send(msg)
            except (FrameError, can.CanError, OSError) as exc:
                raise InjectError(f"FAULT_INJECT {kind}={value:g} not sent: {exc}") from exc
        self.injected.append((kind, value))
        return f"FAULT_INJECT {kind} = {value:g}"
