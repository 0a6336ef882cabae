"""``ehpss-hil monitor --tui``: the monitor's figures as text, redrawn in place twice a second
(ANSI clear-screen; no curses, so it also works over a plain serial console or ``tmux``)."""

from __future__ import annotations

import math
import signal
import sys
import threading
import time
from types import FrameType
from typing import Any

from .listener import BusListener

#: redraws per second
TUI_HZ = 2.0
_CLEAR = "\x1b[H\x1b[2J"


def _f(v: Any, scale: float = 1.0, digits: int = 3) -> str:
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "–"
    return f"{float(v) * scale:.{digits}f}"


def _g(v: Any) -> str:
    return "–" if v is None else f"{float(v):.3g}"


def render(st: dict[str, Any], where: str) -> str:
    """The screen for one status snapshot (:meth:`~.state.MonitorState.status`)."""
    v = st["values"]
    idx = "  ".join(f"M{r['slot']}:θ{_f(r['theta'])} J{_g(r['j'])}" for r in st["index"]) or "–"
    verdicts = "  ".join(f"{k} {n}" for k, n in st["verdicts"].items() if n) or "–"
    lines = [
        f"ehpss-hil monitor · {where}",
        f"[{st['banner']['level'].upper()}] {st['banner']['text']}",
        "",
        f"state {st.get('state', '–')}   mode {st.get('mode', '–')}   "
        f"fail-safe {st.get('failsafe_reason', '–')}   fallback {st.get('fallback', '–')} "
        f"({st.get('fallback_reason', '–')})",
        f"active model  spool M{st.get('active_spool', '–')}   position M{st.get('active_position', '–')}"
        f"   switches {st.get('switches', '–')}",
        f"k̂_LOE {_f(v['k_loe_hat'])}  k̂_DFT {_f(v['k_dft_hat'])}   true k_LOE {_f(v['k_loe_true'])} "
        f"k_Q {_f(st.get('k_q_true'))} k_DFT {_f(v['k_dft_true'])}",
        f"x {_f(v['x_true_m'], 1e3)} mm   y_s {_f(v['y_s_m'], 1e3)} mm   "
        f"x_d {_f(v['x_d_m'], 1e3)} mm ({st['reference']})"
        f"   e {_f(v['e_m'], 1e6, 1)} µm   i {_f(v['i_cmd_a'], 1e3, 2)} mA",
        f"J  {idx}",
        f"overruns {st.get('overruns', '–')}   CycleTimeMax {_f(st.get('cycle_time_max_s'), 1e6, 0)} µs"
        f"   rejected (ctrl) {st.get('ctrl_rejected', '–')}",
        f"bus load {_f(st['bus_load'], 100, 1)} %   {_f(st['frames_per_s'], 1, 0)} frames/s   "
        f"rejected {_f(st['rejected_per_s'], 1, 1)}/s",
        f"verdicts  {verdicts}",
    ]
    return "\n".join(lines)


def run_tui(listener: BusListener, where: str, duration_s: float = 0.0) -> None:
    """Redraw until SIGINT/SIGTERM, ``duration_s`` (s; 0: no limit) or the listener's end."""
    stop = threading.Event()

    def on_signal(signum: int, frame: FrameType | None) -> None:
        stop.set()

    old = {s: signal.signal(s, on_signal) for s in (signal.SIGINT, signal.SIGTERM)}
    end = time.monotonic() + duration_s if duration_s > 0 else math.inf
    try:
        while not stop.is_set() and listener.alive and time.monotonic() < end:
            with listener.lock:
                st = listener.state.status(time.time())
            sys.stdout.write(_CLEAR + render(st, where) + "\n")
            sys.stdout.flush()
            stop.wait(1.0 / TUI_HZ)
    finally:
        for s, h in old.items():
            signal.signal(s, h)
