"""The monitor's local web page: aiohttp serves ``static/`` (the page, its script and uPlot, all
from the package: no CDN, benches are often offline) and pushes the bus state over a WebSocket.

Endpoints: ``/`` the page; ``/static/…``; ``/ws`` a WebSocket that sends, ``refresh_hz`` times a
second, ``{"rows": {column: [values…]}, "status": {…}}`` with the rows added since its last
message (:class:`~.state.MonitorState`); ``/api/config`` (options, kinds, row fields, the
process id); ``/api/status`` (one snapshot, for scripts); ``POST /api/inject``
``{"kind": "k_loe", "value": 0.5}`` with the header ``X-Monitor-Token`` → one FAULT_INJECT frame
(403 unless the monitor was started with ``--allow-inject``; the answer's ``ack_after`` is the
count of FAULT_INJECT_ACK frames heard before it, so the page knows which answer is this
injection's); ``POST /api/capture`` ``{"trigger": "event"|"threshold", "before_s", "after_s",
"field", "level"}`` (token) arms a triggered capture (:mod:`.capture`, with ``--capture-dir``);
``GET /api/capture/NAME`` one of its files. Every request passes the checks of :mod:`.access`
(Host, Origin, token, rates, client count).

Slow readers: each WebSocket has at most one message in flight; a push that finds the previous
one still being written is dropped (counted) and the next carries the rows since the last one
sent, so a stalled client costs one message of memory and no CPU beyond its own tick.

The event loop only copies snapshots out of the state and serializes them; decoding happens in
the listener's thread, so the page's cost does not grow with the bus's frame rate.
"""

from __future__ import annotations

import asyncio
import json
import os
import re
import signal
import socket
import time
from importlib import resources
from pathlib import Path
from typing import Any

from aiohttp import WSMsgType, web

from ..errors import CaptureError, InjectError, ServeError
from ..reasons import FAILSAFE_COLORS, FALLBACK_COLORS, UNKNOWN_COLOR
from .access import TOKEN_HEADER, AccessPolicy, allowed_hosts, middleware
from .capture import CaptureSpec
from .listener import BusListener
from .state import ROW_FIELDS

#: default pushes per second to each page
REFRESH_HZ = 20.0
#: at most this many rows go to a page when it connects (the last 10 s at the default row period)
INITIAL_ROWS = 1000
#: the kernel's send buffer and the user-space write buffer of each WebSocket: with the one
#: message in flight, about what a stalled reader costs the monitor at most
CLIENT_BUFFER_BYTES = 64 * 1024
_CLIENT_BUFFER: web.AppKey[int] = web.AppKey("client_buffer", int)
STATIC_DIR = Path(str(resources.files(__package__) / "static"))
_LISTENER: web.AppKey[BusListener] = web.AppKey("listener", BusListener)
_OPTIONS: web.AppKey[dict[str, Any]] = web.AppKey("options", dict)
_POLICY: web.AppKey[AccessPolicy] = web.AppKey("policy", AccessPolicy)
#: the names of capture files (capture-NNN-YYYYmmddTHHMMSS.log|csv): nothing else is served
_CAPTURE_FILE = re.compile(r"^capture-\d{3}-\d{8}T\d{6}\.(log|csv)$")


def _policy(request: web.Request) -> AccessPolicy:
    return request.app[_POLICY]


def make_app(
    listener: BusListener,
    policy: AccessPolicy,
    refresh_hz: float = REFRESH_HZ,
    title: str = "",
    client_buffer_bytes: int = CLIENT_BUFFER_BYTES,
) -> web.Application:
    """The aiohttp application of one monitor (``policy``: its access checks; the hosts are
    filled in once the port is bound)."""
    app = web.Application(middlewares=[middleware(_policy)])
    app[_LISTENER] = listener
    app[_POLICY] = policy
    app[_CLIENT_BUFFER] = client_buffer_bytes
    app[_OPTIONS] = {
        "allow_inject": listener.allow_inject,
        "kinds": [k for k in listener.kinds if k != "clear"],
        "refresh_hz": refresh_hz,
        "fields": list(ROW_FIELDS),
        "title": title,
        "pid": os.getpid(),  # for benchmarks that measure the monitor's CPU use
        "choices": {
            k: listener.state.choices.get(k, {}) for k in ("State", "FailsafeReason", "FallbackReason")
        },
        "reason_colors": {"FAULT": FAILSAFE_COLORS, "fallback": FALLBACK_COLORS, "unknown": UNKNOWN_COLOR},
        "capture": listener.capture_dir is not None,
    }
    app.router.add_get("/", _index)
    app.router.add_get("/ws", _websocket)
    app.router.add_get("/api/config", _config)
    app.router.add_get("/api/status", _status)
    app.router.add_post("/api/inject", _inject)
    app.router.add_post("/api/capture", _capture)
    app.router.add_get("/api/capture/{name}", _capture_file)
    app.router.add_static("/static/", STATIC_DIR, follow_symlinks=False)
    return app


async def _index(request: web.Request) -> web.StreamResponse:
    return web.FileResponse(STATIC_DIR / "index.html")


async def _config(request: web.Request) -> web.Response:
    opts = request.app[_OPTIONS].copy()
    if opts["allow_inject"] or opts["capture"]:  # this page only: no CORS headers, Host checked
        opts["token"] = request.app[_POLICY].token
    return web.json_response(opts)


def _snapshot(listener: BusListener, seq: int) -> tuple[dict[str, Any], int]:
    with listener.lock:
        st = listener.state.status(time.time())
        rows = listener.state.rows_since(max(seq, st["seq"] - INITIAL_ROWS))
        cap = listener.capture
        st["capture"] = cap.summary(listener.state.status_t0()) if cap is not None else None
    return {"rows": rows, "status": st}, st["seq"]


async def _status(request: web.Request) -> web.Response:
    snap, _ = _snapshot(request.app[_LISTENER], 1 << 62)
    return web.json_response(snap["status"])


async def _websocket(request: web.Request) -> web.StreamResponse:
    pol = request.app[_POLICY]
    if pol.clients >= pol.max_clients:
        pol.count("clients")
        return web.json_response({"error": f"at most {pol.max_clients} live clients"}, status=503)
    limit = request.app[_CLIENT_BUFFER]
    ws = web.WebSocketResponse(writer_limit=limit)
    transport = request.transport
    if transport is not None:  # what a reader that stops reading can hold, kernel and user space
        transport.set_write_buffer_limits(high=limit)
        sock = transport.get_extra_info("socket")
        if sock is not None:
            sock.setsockopt(socket.SOL_SOCKET, socket.SO_SNDBUF, limit)
    await ws.prepare(request)
    pol.clients += 1
    listener = request.app[_LISTENER]
    period = 1.0 / request.app[_OPTIONS]["refresh_hz"]

    async def pump() -> None:
        seq = 0
        sending: asyncio.Task[None] | None = None
        next_t = time.monotonic()
        while not ws.closed:
            if sending is None or sending.done():
                snap, seq = _snapshot(listener, seq)
                sending = asyncio.create_task(ws.send_str(json.dumps(snap, separators=(",", ":"))))
            else:  # the previous message is still being written: a slow reader, drop this one
                pol.count("dropped_pushes")
            next_t += period
            delay = next_t - time.monotonic()
            if delay < 0:  # late (a slow page or host): skip ahead instead of bursting
                next_t, delay = time.monotonic(), 0.0
            await asyncio.sleep(delay)
        if sending is not None:
            sending.cancel()

    task = asyncio.create_task(pump())
    try:
        async for msg in ws:  # the page sends nothing; this waits for the close
            if msg.type == WSMsgType.ERROR:
                break
    finally:
        pol.clients -= 1
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
    refused = _guard(request)
    if refused is not None:
        return refused
    try:
        body = await request.json()
        kind, value = str(body["kind"]), float(body["value"])
    except (ValueError, KeyError, TypeError):
        return web.json_response({"error": 'expected {"kind": NAME, "value": NUMBER}'}, status=400)
    with listener.lock:
        acks = listener.state.acks_seen
    try:
        sent = listener.inject(kind, value)
    except InjectError as exc:
        return web.json_response({"error": str(exc)}, status=400)
    return web.json_response({"sent": sent, "ack_after": acks})


def _guard(request: web.Request) -> web.Response | None:
    """The token and rate checks of a request that acts (inject, capture): None when it passes."""
    pol = request.app[_POLICY]
    if not pol.token_ok(request.headers.get(TOKEN_HEADER)):
        pol.count("token")
        return web.json_response({"error": f"missing or wrong {TOKEN_HEADER}"}, status=403)
    if not pol.inject_rate.take():
        pol.count("rate")
        return web.json_response({"error": "too many requests: at most 5 per second"}, status=429)
    return None


async def _capture(request: web.Request) -> web.Response:
    refused = _guard(request)
    if refused is not None:
        return refused
    try:
        body = await request.json()
        spec = CaptureSpec(
            trigger=str(body.get("trigger", "event")),
            before_s=float(body.get("before_s", 2.0)),
            after_s=float(body.get("after_s", 2.0)),
            field=str(body.get("field", "e_m")),
            level=float(body.get("level", 0.0)),
        )
        summary = request.app[_LISTENER].arm(spec)
    except (ValueError, TypeError, AttributeError) as exc:  # CaptureError is a ValueError
        msg = str(exc) if isinstance(exc, CaptureError) else "expected a JSON object of numbers and names"
        return web.json_response({"error": msg}, status=400)
    return web.json_response(summary)


async def _capture_file(request: web.Request) -> web.StreamResponse:
    name = request.match_info["name"]
    folder = request.app[_LISTENER].capture_dir
    if folder is None or not _CAPTURE_FILE.match(name) or not (folder / name).is_file():
        return web.json_response({"error": "no such capture file"}, status=404)
    kind = "text/csv" if name.endswith(".csv") else "text/plain"
    headers = {"Content-Disposition": f'attachment; filename="{name}"'}
    return web.FileResponse(folder / name, headers={**headers, "Content-Type": kind})


def serve(
    listener: BusListener,
    host: str,
    port: int,
    refresh_hz: float = REFRESH_HZ,
    title: str = "",
    extra_hosts: tuple[str, ...] = (),
) -> None:
    """Serve the page until SIGINT/SIGTERM or until the listener's thread ends; prints
    ``monitor: http://HOST:PORT/`` (the port the system chose when ``port`` is 0) and, with
    injection on, the token scripts need."""
    policy = AccessPolicy(hosts=frozenset())
    app = make_app(listener, policy, refresh_hz, title)
    asyncio.run(_serve(app, listener, host, port, extra_hosts))


async def _serve(
    app: web.Application, listener: BusListener, host: str, port: int, extra_hosts: tuple[str, ...]
) -> None:
    runner = web.AppRunner(app, access_log=None, handle_signals=False)
    await runner.setup()
    site = web.TCPSite(runner, host, port)
    try:
        await site.start()
    except OSError as exc:
        await runner.cleanup()
        raise ServeError(f"cannot listen on {host}:{port}: {exc.strerror or exc}") from exc
    bound = runner.addresses[0]
    policy = app[_POLICY]
    policy.hosts = allowed_hosts(host, bound[1], extra_hosts)
    print(f"monitor: http://{host}:{bound[1]}/ (Ctrl-C to stop)", flush=True)
    if listener.allow_inject:
        print(f"injection token (header {TOKEN_HEADER}): {policy.token}", flush=True)
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
        if any(policy.refused.values()):
            print(f"monitor: refused {policy.refused}", flush=True)
        await runner.cleanup()
