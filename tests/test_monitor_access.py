"""The monitor's page server is no open door (monitor/access.py): real HTTP and WebSocket requests
over 127.0.0.1 against the real aiohttp app, the listener on a real python-can ``virtual`` bus
whose peer sees every FAULT_INJECT that goes out. A hostile page's requests are imitated by
their headers (what a browser sends: ``Origin`` of the other page, ``Host`` of a rebound name);
``tests/test_monitor_origins.py`` has a real second origin in headless Chromium."""

from __future__ import annotations

import asyncio
import uuid
from typing import Any

import aiohttp
import can
import pytest
from aiohttp.test_utils import TestClient, TestServer

from ehpss_hil.codec import FrameCodec
from ehpss_hil.monitor.access import INJECT_BURST, AccessPolicy, allowed_hosts
from ehpss_hil.monitor.listener import BusListener
from ehpss_hil.monitor.server import make_app
from ehpss_hil.monitor.state import MonitorState, choice_names

BODY = {"kind": "k_loe", "value": 0.5}


class Bench:
    """A listener with injection on, its app on 127.0.0.1, and the bus peer that receives."""

    def __init__(self, max_clients: int = 16) -> None:
        channel = f"acc-{uuid.uuid4().hex}"
        codec = FrameCodec()
        self.listener = BusListener(
            lambda: can.Bus(interface="virtual", channel=channel, receive_own_messages=False),
            codec,
            MonitorState(choice_names(codec)),
            tx_codec=FrameCodec(),
            allow_inject=True,
        )
        self.peer = can.Bus(interface="virtual", channel=channel, receive_own_messages=False)
        self.policy = AccessPolicy(hosts=frozenset(), max_clients=max_clients)

    def injections_on_the_bus(self) -> int:
        n = 0
        while (m := self.peer.recv(timeout=0.2)) is not None:
            n += FrameCodec().name_of(m.arbitration_id) == "FAULT_INJECT"
        return n

    def close(self) -> None:
        self.listener.stop()
        self.peer.shutdown()


@pytest.fixture
def bench() -> Any:
    b = Bench()
    b.listener.start()
    yield b
    b.close()


def _run(bench: Bench, scenario: Any, **app: Any) -> Any:
    async def go() -> Any:
        server = TestServer(make_app(bench.listener, bench.policy, **app), host="127.0.0.1")
        async with TestClient(server) as c:
            bench.policy.hosts = allowed_hosts("127.0.0.1", c.port or 0)
            return await scenario(c, f"127.0.0.1:{c.port}")

    return asyncio.run(go())


def test_cross_origin_and_rebound_injections_are_refused(bench: Bench) -> None:
    async def scenario(c: TestClient, host: str) -> dict[str, int]:
        token = (await (await c.get("/api/config")).json())["token"]
        ok = {"X-Monitor-Token": token}
        out = {}
        for name, headers in {
            "evil origin": {**ok, "Origin": "http://evil.example"},
            "null origin": {**ok, "Origin": "null"},
            "other port": {**ok, "Origin": "http://127.0.0.1:1"},
            "rebound host": {**ok, "Host": "evil.example:8050"},
            "no token": {"Origin": f"http://{host}"},
            "wrong token": {"Origin": f"http://{host}", "X-Monitor-Token": token[:-1] + "x"},
            "page": {**ok, "Origin": f"http://{host}"},
            "script": ok,
        }.items():
            out[name] = (await c.post("/api/inject", json=BODY, headers=headers)).status
        return out

    got = _run(bench, scenario)
    assert got == {
        "evil origin": 403,
        "null origin": 403,
        "other port": 403,
        "rebound host": 421,
        "no token": 403,
        "wrong token": 403,
        "page": 200,
        "script": 200,
    }
    assert bench.injections_on_the_bus() == 2  # the page's and the script's only
    assert bench.policy.refused == {"origin": 3, "host": 1, "token": 2}


def test_a_rebound_page_cannot_read_the_token_or_the_data(bench: Bench) -> None:
    async def scenario(c: TestClient, host: str) -> tuple[int, int, int]:
        rebound = {"Host": "evil.example:8050"}
        cfg = (await c.get("/api/config", headers=rebound)).status
        status = (await c.get("/api/status", headers=rebound)).status
        page = (await c.get("/", headers=rebound)).status
        return cfg, status, page

    assert _run(bench, scenario) == (421, 421, 421)


def test_cross_origin_websockets_are_refused(bench: Bench) -> None:
    async def scenario(c: TestClient, host: str) -> tuple[int, bool]:
        try:
            await c.ws_connect("/ws", headers={"Origin": "http://evil.example"})
            refused = 101
        except aiohttp.WSServerHandshakeError as exc:
            refused = exc.status
        ws = await c.ws_connect("/ws", headers={"Origin": f"http://{host}"})
        first = await ws.receive_json(timeout=30)
        await ws.close()
        return refused, set(first) == {"rows", "status"}

    assert _run(bench, scenario) == (403, True)


def test_injections_are_rate_limited(bench: Bench) -> None:
    async def scenario(c: TestClient, host: str) -> list[int]:
        token = (await (await c.get("/api/config")).json())["token"]
        return [
            (await c.post("/api/inject", json=BODY, headers={"X-Monitor-Token": token})).status
            for _ in range(200)
        ]

    statuses = _run(bench, scenario)
    sent = statuses.count(200)
    # the burst at once, then 5 per second for however long 200 requests took: far fewer than 200
    assert INJECT_BURST <= sent < 100 and statuses.count(429) == 200 - sent
    assert bench.injections_on_the_bus() == sent


def test_clients_are_capped() -> None:
    b = Bench(max_clients=3)
    b.listener.start()
    try:

        async def scenario(c: TestClient, host: str) -> tuple[list[int], int]:
            socks = [await c.ws_connect("/ws") for _ in range(3)]
            try:
                await c.ws_connect("/ws")
                fourth = 101
            except aiohttp.WSServerHandshakeError as exc:
                fourth = exc.status
            for s in socks:
                await s.close()
            await asyncio.sleep(0.2)
            again = await c.ws_connect("/ws")  # a place is free again
            await again.close()
            return [fourth], b.policy.refused.get("clients", 0)

        assert _run(b, scenario) == ([503], 1)
    finally:
        b.close()


def test_allowed_hosts() -> None:
    assert allowed_hosts("127.0.0.1", 8050) == {"127.0.0.1:8050", "localhost:8050", "[::1]:8050"}
    assert "bench-pc:9000" in allowed_hosts("127.0.0.1", 9000, ["bench-pc"])
    assert allowed_hosts("192.0.2.7", 80) == {"192.0.2.7:80"}


def test_a_stalled_reader_has_its_pushes_dropped_not_queued(bench: Bench) -> None:
    """A client that completes the WebSocket handshake and then never reads: the server keeps
    one message in flight for it and drops the rest (counted); another client still gets its
    pushes."""
    import base64
    import os
    import socket

    async def scenario(c: TestClient, host: str) -> tuple[int, int]:
        codec = FrameCodec()  # rows for the state: the first push to a client carries 1000 of them
        for k in range(3000):
            bench.peer.send(codec.encode("SENSOR_POS", {"Position": k * 1e-7, "Spool": 0.0}))
            if k % 100 == 0:
                await asyncio.sleep(0.01)
        s = socket.socket()
        s.setsockopt(socket.SOL_SOCKET, socket.SO_RCVBUF, 4096)
        s.connect(("127.0.0.1", c.port or 0))
        key = base64.b64encode(os.urandom(16)).decode()
        s.sendall(
            f"GET /ws HTTP/1.1\r\nHost: {host}\r\nUpgrade: websocket\r\nConnection: Upgrade\r\n"
            f"Sec-WebSocket-Key: {key}\r\nSec-WebSocket-Version: 13\r\n\r\n".encode()
        )
        for _ in range(200):  # until the first pushes found the stalled one still in flight
            await asyncio.sleep(0.05)
            if bench.policy.refused.get("dropped_pushes", 0) >= 5:
                break
        ws = await c.ws_connect("/ws")
        got = 0
        for _ in range(5):
            await ws.receive_json(timeout=30)
            got += 1
        await ws.close()
        s.close()
        return bench.policy.refused.get("dropped_pushes", 0), got

    # small buffers and fast pushes, so that the stalled reader's fill up within a second
    dropped, got = _run(bench, scenario, refresh_hz=100.0, client_buffer_bytes=4096)
    assert dropped >= 5 and got == 5
