"""The tuning panel's door: a secret path, loopback Host names, the panel's own Origin.

Binding to 127.0.0.1 keeps other machines out, not other origins: any web page open in the
user's browser can make that browser talk to a loopback port. Two attacks follow, and Viser 1.1
stops neither (it checks no ``Origin``, no ``Host`` and has no secret):

- **cross-site WebSocket**: a page on ``https://evil.example`` opens
  ``ws://127.0.0.1:PORT``; browsers allow it and send ``Origin: https://evil.example``;
- **DNS rebinding**: ``evil.example`` resolves first to the attacker's server, then to
  127.0.0.1; the page is then *same-origin* with the panel and can read it over HTTP, and
  the browser sends ``Host: evil.example:PORT``.

:class:`PanelGuard` refuses, with HTTP 403 and before any WebSocket upgrade, every request

1. whose path does not start with ``/<token>/`` (or is ``/<token>``): the token is 32 random
   bytes that only the printed panel address carries, so a page (or another local program)
   that does not know it gets nothing; it is a *path* token, not ``?token=``, because Viser's
   page builds its WebSocket address from its own address minus the query (a page at
   ``/<token>/`` connects to ``ws://HOST:PORT/<token>``, which passes);
2. whose ``Host`` is not a loopback name (``127.0.0.1``, ``localhost``, ``::1``) or the
   ``--host`` the user chose (on 0.0.0.0 / ``::`` also the machine's own names and any IP
   literal: a rebinding attack needs a name it controls, never an address);
3. that carries an ``Origin`` other than ``http://<allowed host>:<this port>``. Browsers send
   ``Origin`` on every WebSocket handshake; programs other than browsers need not, and for
   them the token is the lock.

The guard sits in front of Viser's own ``process_request`` (the function by which its
``websockets`` server serves the static page), which sees every request before the upgrade.
Viser builds that server inside a background thread and keeps no handle on it, so
:func:`guarded_viser_server` wraps ``websockets.asyncio.server.serve`` for the few
milliseconds of ``ViserServer(...)`` (under a lock) and puts the guard in. If Viser ever stops
calling it that way, the panel does not start: the check is that the guard *was* installed.
"""

from __future__ import annotations

import contextlib
import dataclasses
import hmac
import http
import io
import ipaddress
import secrets
import socket
import threading
from collections.abc import Awaitable, Callable
from typing import Any
from urllib.parse import urlsplit

from websockets.asyncio.server import ServerConnection
from websockets.http11 import Request, Response

from radarviz.viz_app.rerun.viewer import ServiceError

ProcessRequest = Callable[[ServerConnection, Request], Awaitable[Response | None] | Response | None]

LOOPBACK_NAMES: frozenset[str] = frozenset({"127.0.0.1", "localhost", "::1"})
WILDCARDS: frozenset[str] = frozenset({"0.0.0.0", "::", ""})

_SERVE_LOCK = threading.Lock()


def _host_name(authority: str) -> str:
    """The host part of a ``Host`` header or URL authority, lower case, IPv6 brackets off."""
    authority = authority.strip().lower()
    if authority.startswith("["):
        # "[addr]" or "[addr]:port" only: "[::1].evil.example:PORT" names evil.example's host,
        # not the loopback address (a rebinding page's Host), so it gives no name at all.
        addr, close, rest = authority[1:].partition("]")
        port_ok = rest == "" or (rest.startswith(":") and rest[1:].isdigit())
        return addr if close and port_ok else ""
    return authority.rsplit(":", 1)[0] if authority.count(":") == 1 else authority


def _is_ip(name: str) -> bool:
    try:
        ipaddress.ip_address(name)
    except ValueError:
        return False
    return True


@dataclasses.dataclass(frozen=True)
class PanelGuard:
    """The checks of one panel server (module docstring): token, Host names, Origin.

    ``host`` is the user's ``--host``, ``bind`` the address it resolved to (what the server
    binds; a name such as ``localhost`` is bound as its address). ``allowed_names`` always holds
    the loopback names, ``host`` and ``bind``; a wildcard ``host`` adds the machine's own names
    and lets any IP literal through (see the module docstring).
    """

    host: str = "127.0.0.1"
    bind: str | None = None
    token: str = dataclasses.field(default_factory=lambda: secrets.token_urlsafe(32))

    @property
    def wildcard(self) -> bool:
        return self.host in WILDCARDS

    @property
    def allowed_names(self) -> frozenset[str]:
        names = set(LOOPBACK_NAMES)
        if not self.wildcard:
            names.update(h.strip("[]").lower() for h in (self.host, self.bind or self.host))
        else:
            with contextlib.suppress(OSError):
                names.update({socket.gethostname().lower(), socket.getfqdn().lower()})
        return frozenset(names)

    def host_allowed(self, name: str) -> bool:
        return name in self.allowed_names or (self.wildcard and _is_ip(name))

    def url(self, connect_host: str, port: int) -> str:
        """The address to print and open: the only one the guard lets in."""
        shown = f"[{connect_host}]" if ":" in connect_host else connect_host
        return f"http://{shown}:{port}/{self.token}/"

    def refusal(self, request: Request, port: int) -> str | None:
        """Why ``request`` (on a socket listening on ``port``) is refused, or None."""
        path = request.path.partition("?")[0]
        first = path.split("/")[1] if path.startswith("/") else ""
        if not hmac.compare_digest(first.encode(), self.token.encode()):
            return "the panel's address (with its token) is the one `radarviz tune` printed"
        host = _host_name(request.headers.get("Host", ""))
        if not self.host_allowed(host):
            return f"Host {host or '(none)'!r} is not this panel's"
        origin = request.headers.get("Origin")
        if origin is not None:
            parts = urlsplit(origin)
            try:
                origin_port = parts.port or 80
            except ValueError:
                origin_port = -1
            if (
                parts.scheme != "http"
                or not self.host_allowed((parts.hostname or "").lower())
                or origin_port != port
            ):
                return f"Origin {origin!r} is not this panel's"
        return None

    def strip(self, request: Request) -> Request:
        """``request`` with the token taken off its path (``/<token>/x?q`` → ``/x?q``)."""
        rest = request.path[len(self.token) + 1 :]
        if not rest.startswith("/"):
            rest = "/" + rest
        return dataclasses.replace(request, path=rest)

    def wrap(self, inner: ProcessRequest | None) -> ProcessRequest:
        """A ``process_request`` that refuses (403) or hands the stripped request to ``inner``."""

        def process_request(
            connection: ServerConnection, request: Request
        ) -> Awaitable[Response | None] | Response | None:
            port = int(connection.local_address[1])
            reason = self.refusal(request, port)
            if reason is not None:
                return connection.respond(http.HTTPStatus.FORBIDDEN, f"forbidden: {reason}\n")
            return inner(connection, self.strip(request)) if inner is not None else None

        return process_request


def guarded_viser_server(
    guard: PanelGuard,
    port: int,
    wrap: Callable[[ProcessRequest | None], ProcessRequest] | None = None,
    **kwargs: Any,
) -> Any:
    """``viser.ViserServer(host=guard.bind, port=port, ...)`` with ``guard`` before every request.

    ``wrap``, if given, goes between the guard and Viser's own ``process_request`` (the panel
    page, ``tune.page.serve_page``): it sees only requests the guard let through.

    Raises ServiceError (after stopping the server) if Viser did not build its server through
    ``websockets.asyncio.server.serve`` with a ``process_request``: an unguarded panel never
    runs. Viser prints a box with its address *without* the token (a page that answers 403);
    it is swallowed, so the only address shown is :meth:`PanelGuard.url`.
    """
    import viser
    import websockets.asyncio.server as ws_server

    installed: list[bool] = []
    original = ws_server.serve

    def serve(*args: Any, **serve_kwargs: Any) -> Any:
        if "process_request" in serve_kwargs and not installed:
            inner = serve_kwargs["process_request"]
            serve_kwargs["process_request"] = guard.wrap(wrap(inner) if wrap else inner)
            installed.append(True)
        return original(*args, **serve_kwargs)

    with _SERVE_LOCK:
        ws_server.serve = serve
        try:
            with contextlib.redirect_stdout(io.StringIO()):
                server = viser.ViserServer(host=guard.bind or guard.host, port=port, **kwargs)
        finally:
            ws_server.serve = original
    if not installed:
        with contextlib.suppress(Exception):
            server.stop()
        raise ServiceError("this viser version cannot be guarded: the panel does not start")
    return server
