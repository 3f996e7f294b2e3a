"""The panel's page: the Viser controls and the Rerun viewer side by side in one window.

``radarviz tune`` prints one address. Its page (:func:`panel_page`) holds two frames: on the
left the Viser controls (Viser's own page, at the same address with ``?controls``), on the
right the Rerun web viewer, served by the ``rerun`` child on its own loopback port. The
controls' frame is wide enough for Viser's desktop layout (narrower than ``CONTROLS_MIN_PX``
Viser switches to its phone layout, a bottom sheet under an empty canvas); the panel docks
its controls across that whole frame, so Viser's own 3D canvas (unused here) gets no room.

:func:`serve_page` answers the page in front of Viser's ``process_request``; every other
request (Viser's assets, its WebSocket, ``?controls``) goes on to Viser unchanged. It sits
behind ``tune.guard``, so the page, too, is only given to requests with the token.
"""

from __future__ import annotations

import html
import http
from collections.abc import Awaitable, Callable

from websockets.asyncio.server import ServerConnection
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from radarviz.viz_app.rerun.viewer import LOOPBACK, viewer_url

ProcessRequest = Callable[[ServerConnection, Request], Awaitable[Response | None] | Response | None]

#: Width of the controls' frame, px. Viser's phone layout starts at 36 em (576 px) and below.
CONTROLS_MIN_PX = 580
#: The query that asks for Viser's own page (the controls) instead of the two-frame page.
CONTROLS_QUERY = "controls"


def embedded_viewer_url(connect_host: str, web_port: int, grpc_port: int) -> str:
    """The viewer's address for the page's frame: as ``viewer_url``, but on ``localhost``
    when the servers are on 127.0.0.1.

    Chromium keeps frames of one site (scheme and host, any port) in one renderer process,
    so a viewer frame on ``127.0.0.1`` would share the controls' main thread, and the
    controls would freeze while the viewer takes in a run (seconds with software WebGL).
    ``localhost`` is another site on the same loopback address: the viewer gets a process
    of its own. Its gRPC source stays on ``connect_host``.
    """
    url = viewer_url(connect_host, web_port, grpc_port)
    if connect_host == LOOPBACK:
        url = url.replace(f"http://{LOOPBACK}:{web_port}/", f"http://localhost:{web_port}/", 1)
    return url


def panel_page(viewer_url: str, title: str = "radarviz tune") -> str:
    """The two-frame page: the controls (``./?controls``) and the viewer at ``viewer_url``."""
    viewer = html.escape(viewer_url, quote=True)
    return f"""<!doctype html>
<html lang="en"><head><meta charset="utf-8"><title>{html.escape(title)}</title>
<style>
  html, body {{ margin: 0; height: 100%; overflow: hidden; font-family: sans-serif; }}
  #panel {{ display: flex; height: 100vh; }}
  #controls {{ width: {CONTROLS_MIN_PX}px; flex: none; border: 0;
              border-right: 1px solid #d0d0d0; }}
  #viewer-column {{ flex: 1; display: flex; flex-direction: column; min-width: 0; }}
  #viewer {{ flex: 1; border: 0; width: 100%; }}
  #viewer-link {{ font-size: 12px; padding: 2px 8px; color: #555; background: #f4f4f4; }}
</style></head>
<body><div id="panel">
  <iframe id="controls" title="controls" src="./?{CONTROLS_QUERY}"></iframe>
  <div id="viewer-column">
    <iframe id="viewer" title="Rerun viewer" src="{viewer}" allow="fullscreen"></iframe>
    <div id="viewer-link">Rerun viewer: each change re-runs the scene and the viewer switches
      to the new run · <a href="{viewer}" target="_blank" rel="noopener">open it alone</a></div>
  </div>
</div></body></html>
"""


def serve_page(inner: ProcessRequest | None, page: str) -> ProcessRequest:
    """A ``process_request`` that answers ``GET /`` (no query, no WebSocket upgrade) with
    ``page`` and hands every other request to ``inner`` (Viser's)."""
    body = page.encode()

    def process_request(
        connection: ServerConnection, request: Request
    ) -> Awaitable[Response | None] | Response | None:
        path, _, query = request.path.partition("?")
        upgrade = request.headers.get("Upgrade", "").lower() == "websocket"
        if path == "/" and not query and not upgrade:
            headers = Headers(
                [
                    ("Content-Type", "text/html; charset=utf-8"),
                    ("Content-Length", str(len(body))),
                    ("Cache-Control", "no-store"),
                ]
            )
            return Response(http.HTTPStatus.OK.value, "OK", headers, body)
        return inner(connection, request) if inner is not None else None

    return process_request
