"""The monitor's local web page: aiohttp serves ``static/`` (the page, its script and uPlot, all
from the package: no CDN, benches are often offline) and pushes the bus state over a WebSocket.

Endpoints: ``/`` the page; ``/static/…``; ``/ws`` a WebSocket that sends, ``refresh_hz`` times a
second, ``{"rows": {column: [values…]}, "status": {…}}`` with the rows added since its last
message (:class:`~.state.MonitorState`); ``/api/config`` (options, kinds, row fields, the
process id); ``/api/status`` (one snapshot, for scripts); ``POST /api/inject``
``{"kind": "k_loe", "value": 0.5}`` → one FAULT_INJECT frame (403 unless the monitor was started
with ``--allow-inject``).

The event loop only copies snapshots out of the state and serializes them; decoding happens in
the listener's thread, so the page's cost does not grow with the bus's frame rate.
"""

from __future__ import annotations

import asyncio
import json
import os
import signal
import time
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from ..errors import InjectError, ServeError
from .listener import BusListener
from .state import ROW_FIELDS

#: default pushes per second to each page
REFRESH_HZ = 20.0
#: at most this many rows go to a page when it connects (the last 10 s at the default row period)
INITIAL_ROWS = 1000
STATIC_DIR = Path(str(resources.files(__package__) / "static"))
_LISTENER: web.AppKey[BusListener] = web.AppKey("listener", BusListener)
_OPTIONS: web.AppKey[dict[str, Any]] = web.AppKey("options", dict)


def make_app(listener: BusListener, refresh_hz: float = REFRESH_HZ, title: str = "") -> web.Application:
    """The aiohttp application of one monitor."""
    app = web.Application()
    app[_LISTENER] = listener
    app[_OPTIONS] = {
        "allow_inject": listener.allow_inject,
        "kinds": [k for k in listener.kinds if k != "clear"],
        "refresh_hz": refresh_hz,
        "fields": list(ROW_FIELDS),
        "title": title,
        "pid": os.getpid(),  # for benchmarks that measure the monitor's CPU use
    }
    app.router.add_get("/", _index)
    app.router.add_get("/ws", _websocket)
    app.router.add_get("/api/config", _config)
    app.router.add_get("/api/status", _status)
    app.router.add_post("/api/inject", _inject)
    app.router.add_static("/static/", STATIC_DIR, follow_symlinks=False)
    return app


async def _index(request: web.Request) -> web.StreamResponse:
    return web.FileResponse(STATIC_DIR / "index.html")


async def _config(request: web.Request) -> web.Response:
    return web.json_response(request.app[_OPTIONS])


def _snapshot(listener: BusListener, seq: int) -> tuple[dict[str, Any], int]:
    with listener.lock:
        st = listener.state.status(time.time())
        rows = listener.state.rows_since(max(seq, st["seq"] - INITIAL_ROWS))
    return {"rows": rows, "status": st}, st["seq"]


async def _status(request: web.Request) -> web.Response:
    snap, _ = _snapshot(request.app[_LISTENER], 1 << 62)
    return web.json_response(snap["status"])


async def _websocket(request: web.Request) -> web.WebSocketResponse:
    ws = web.WebSocketResponse()
    await ws.prepare(request)
    listener = request.app[_LISTENER]
    period = 1.0 / request.app[_OPTIONS]["refresh_hz"]

    async def pump() -> None:
        seq = 0
        next_t = time.monotonic()
        while not ws.closed:
            snap, seq = _snapshot(listener, seq)
            await ws.send_str(json.dumps(snap, separators=(",", ":")))
            next_t += period
            delay = next_t - time.monotonic()
            if delay < 0:  # late (a slow page or host): skip ahead instead of bursting
                next_t, delay = time.monotonic(), 0.0
            await asyncio.sleep(delay)

    task = asyncio.create_task(pump())
    try:
        async for msg in ws:  # the page sends nothing; this waits for the close
            if msg.type == WSMsgType.ERROR:
                break
    finally:
        task.cancel()
        try:
            await task
        except (asyncio.CancelledError, ConnectionError):
            pass
    return ws


async def _inject(request: web.Request) -> web.Response:
    listener = request.app[_LISTENER]
    if not listener.allow_inject:
        return web.json_response({"error": "fault injection is off (--allow-inject)"}, status=403)
    try:
        body = await request.json()
        kind, value = str(body["kind"]), float(body["value"])
    except (ValueError, KeyError, TypeError):
        return web.json_response({"error": 'expected {"kind": NAME, "value": NUMBER}'}, status=400)
    try:
        sent = listener.inject(kind, value)
    except InjectError as exc:
        return web.json_response({"error": str(exc)}, status=400)
    return web.json_response({"sent": sent})


def serve(
    listener: BusListener, host: str, port: int, refresh_hz: float = REFRESH_HZ, title: str = ""
) -> None:
    """Serve the page until SIGINT/SIGTERM or until the listener's thread ends; prints
    ``monitor: http://HOST:PORT/`` (the port the system chose when ``port`` is 0)."""
    asyncio.run(_serve(make_app(listener, refresh_hz, title), listener, host, port))


async def _serve(app: web.Application, listener: BusListener, host: str, port: int) -> None:
    runner = web.AppRunner(app, access_log=None, handle_signals=False)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise ServeError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from exc
    bound = runner.addresses[0]
    print(f"monitor: http://{host}:{bound[1]}/ (Ctrl-C to stop)", flush=True)
    stop = asyncio.Event()
    loop = asyncio.get_running_loop()
    for s in (signal.SIGINT, signal.SIGTERM):
        loop.add_signal_handler(s, stop.set)
    try:
        while not stop.is_set() and listener.alive:
            try:
                await asyncio.wait_for(stop.wait(), timeout=0.5)
            except TimeoutError:
                pass
    finally:
        await runner.cleanup()
