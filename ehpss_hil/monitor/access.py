"""Who may talk to the monitor's page server: the page the monitor served, and scripts on this
host — not another web page the user happens to have open.

A browser lets any page send requests to 127.0.0.1: a "no-cors" POST from another origin, a
WebSocket to any address, or DNS rebinding (a hostile name that resolves to 127.0.0.1, so that
the browser thinks the monitor is that page's own origin). So every request is checked:

- **Host**: the ``Host`` header names the address the page is served on (for a loopback
  address also ``localhost``/``127.0.0.1``/``[::1]``; for a wildcard bind this host's names;
  plus ``--allow-host``). Anything else is refused with 421: a rebinding page sends its own name.
- **Origin**: when a browser sends one (on every POST and every WebSocket of another page) it
  must be one of ``http://<allowed host>``; ``null`` and foreign origins are refused (403).
  Scripts send none and are let through to what the token guards.
- **Token**: injection needs ``X-Monitor-Token`` with a random token made at server start. The
  page reads it from ``/api/config``, which another origin cannot read (no CORS headers), and a
  custom header cannot be sent cross-origin without a CORS preflight the server never grants.
  It is printed beside the URL for scripts; it is never a cookie.
- **Rates and counts**: at most :data:`INJECT_RATE_PER_S` injections per second (burst
  :data:`INJECT_BURST`), 429 beyond; at most :data:`MAX_CLIENTS` live WebSockets, 503 beyond.
"""

from __future__ import annotations

import hmac
import ipaddress
import secrets
import socket
import time
from collections.abc import Awaitable, Callable, Iterable
from dataclasses import dataclass, field

from aiohttp import web

#: injections accepted per second, and the burst above that rate
INJECT_RATE_PER_S = 5.0
INJECT_BURST = 10
#: live WebSocket clients (pages, scripts) at once
MAX_CLIENTS = 16
#: the header that carries the token
TOKEN_HEADER = "X-Monitor-Token"
#: bytes of randomness in the token (urlsafe base64: 22 characters)
TOKEN_BYTES = 16
_LOOPBACK_NAMES = ("localhost", "127.0.0.1", "[::1]")


@dataclass
class RateLimit:
    """A token bucket: :meth:`take` is True while the rate (per s) and burst allow."""

    rate_per_s: float = INJECT_RATE_PER_S
    burst: int = INJECT_BURST
    _level: float = field(default=float(INJECT_BURST), init=False)
    _t: float = field(default_factory=time.monotonic, init=False)

    def take(self) -> bool:
        now = time.monotonic()
        self._level = min(float(self.burst), self._level + (now - self._t) * self.rate_per_s)
        self._t = now
        if self._level >= 1.0:
            self._level -= 1.0
            return True
        return False


@dataclass
class AccessPolicy:
    """The checks of the module docstring for one served address; counters of what was refused."""

    hosts: frozenset[str]
    token: str = field(default_factory=lambda: secrets.token_urlsafe(TOKEN_BYTES))
    max_clients: int = MAX_CLIENTS
    inject_rate: RateLimit = field(default_factory=RateLimit)
    clients: int = 0
    refused: dict[str, int] = field(default_factory=dict)

    @property
    def origins(self) -> frozenset[str]:
        return frozenset(f"http://{h}" for h in self.hosts)

    def count(self, why: str) -> None:
        self.refused[why] = self.refused.get(why, 0) + 1

    def token_ok(self, given: str | None) -> bool:
        return given is not None and hmac.compare_digest(given.encode(), self.token.encode())


def _is_loopback(host: str) -> bool:
    if host == "localhost":
        return True
    try:
        return ipaddress.ip_address(host.strip("[]")).is_loopback
    except ValueError:
        return False


def _is_wildcard(host: str) -> bool:
    return host in ("0.0.0.0", "::", "")


def _with_port(host: str, port: int) -> str:
    h = host.lower()
    if ":" in h and not h.startswith("["):  # a bare IPv6 address
        h = f"[{h}]"
    return f"{h}:{port}"


def allowed_hosts(bind_host: str, port: int, extra: Iterable[str] = ()) -> frozenset[str]:
    """The ``Host`` header values of requests for this server (``host:port``, lower case)."""
    names = {bind_host}
    if _is_loopback(bind_host) or _is_wildcard(bind_host):
        names.update(_LOOPBACK_NAMES)
    if _is_wildcard(bind_host):
        names.update({socket.gethostname(), socket.getfqdn()})
    names.update(extra)
    return frozenset(_with_port(n, port) for n in names if n and not _is_wildcard(n))


Handler = Callable[[web.Request], Awaitable[web.StreamResponse]]


def middleware(
    policy_of: Callable[[web.Request], AccessPolicy],
) -> Callable[..., Awaitable[web.StreamResponse]]:
    """aiohttp middleware: Host and Origin checks on every request."""

    @web.middleware
    async def check(request: web.Request, handler: Handler) -> web.StreamResponse:
        pol = policy_of(request)
        if request.headers.get("Host", "").lower() not in pol.hosts:
            pol.count("host")
            return web.json_response({"error": "this server does not serve that Host"}, status=421)
        origin = request.headers.get("Origin")
        if origin is not None and origin.lower() not in pol.origins:
            pol.count("origin")
            return web.json_response({"error": "cross-origin request refused"}, status=403)
        return await handler(request)

    return check
