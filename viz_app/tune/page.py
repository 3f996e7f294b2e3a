"""The panel's page: the Viser controls and the Rerun viewer side by side in one window.

``radarviz tune`` prints one address. Its page (:func:`panel_page`) holds two frames: on the
left the Viser controls (Viser's own page, at the same address with ``?controls``), on the
right the Rerun web viewer, served by the ``rerun`` child on its own loopback port. The
controls' frame is wide enough for Viser's desktop layout (narrower than ``CONTROLS_MIN_PX``
Viser switches to its phone layout, a bottom sheet under an empty canvas); the panel docks
its controls across that whole frame, so Viser's own 3D canvas (unused here) gets no room.

The page's script tells the panel when the user has finished a value: a slider let go (a
pointer or an arrow key on the slider itself), or Enter in a number box: ``GET
./?finished=VALUE``. Viser sends a slider's steps and the keystrokes typed into a number box
alike, one value per change, so only the page can tell a finished value from a half-typed
one; a finished value runs without the typing pause (``TunePanel.finished``).

:func:`serve_page` answers the page and the reports in front of Viser's ``process_request``;
every other request (Viser's assets, its WebSocket, ``?controls``) goes on to Viser
unchanged. It sits behind ``tune.guard``, so the page and the reports, too, are only taken
from requests with the token.
"""

from __future__ import annotations

import html
import http
import math
from collections.abc import Awaitable, Callable
from urllib.parse import parse_qs

from websockets.asyncio.server import ServerConnection
from websockets.datastructures import Headers
from websockets.http11 import Request, Response

from radarviz.viz_app.rerun.viewer import LOOPBACK, viewer_url

ProcessRequest = Callable[[ServerConnection, Request], Awaitable[Response | None] | Response | None]

#: Width of the controls' frame, px. Viser's phone layout starts at 36 em (576 px) and below.
CONTROLS_MIN_PX = 580
#: The query that asks for Viser's own page (the controls) instead of the two-frame page.
CONTROLS_QUERY = "controls"
#: The query key by which the page reports a value the user has finished.
FINISHED_QUERY = "finished"


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
</div>
<script>
(() => {{
  // A value the user has finished (a slider let go, Enter in a number box) is reported, so
  // the panel runs it without waiting out the typing pause.
  const frame = document.getElementById("controls");
  const steps = new Set(["ArrowLeft", "ArrowRight", "ArrowUp", "ArrowDown", "Home", "End",
                         "PageUp", "PageDown"]);
  const report = (value) => {{
    if (value === null || value.trim() === "") return;
    fetch("./?{FINISHED_QUERY}=" + encodeURIComponent(value.trim()), {{cache: "no-store"}})
      .catch(() => {{}});
  }};
  frame.addEventListener("load", () => {{
    const doc = frame.contentDocument;
    if (!doc) return;
    let held = null;  // the slider a pointer went down on
    doc.addEventListener("pointerdown", (e) => {{
      const root = e.target.closest ? e.target.closest(".mantine-Slider-root") : null;
      held = root ? root.querySelector("[role=slider]") : null;
    }}, true);
    doc.addEventListener("pointerup", () => {{
      if (held) report(held.getAttribute("aria-valuenow"));
      held = null;
    }}, true);
    doc.addEventListener("keyup", (e) => {{
      const t = e.target;
      if (steps.has(e.key) && t.getAttribute && t.getAttribute("role") === "slider") {{
        report(t.getAttribute("aria-valuenow"));
      }}
    }}, true);
    doc.addEventListener("keydown", (e) => {{
      const t = e.target;
      if (e.key === "Enter" && t.tagName === "INPUT" && t.type === "text") report(t.value);
    }}, true);
  }});
}})();
</script>
</body></html>
"""


def finished_value(query: str) -> float | None:
    """The value of a ``finished=VALUE`` report, or None if ``query`` is not one.

    Raises ValueError for a report whose value is not one finite number."""
    fields = parse_qs(query, keep_blank_values=True)
    if set(fields) != {FINISHED_QUERY}:
        return None
    (raw,) = fields[FINISHED_QUERY]
    try:
        value = float(raw)
    except ValueError:
        value = math.nan
    if not math.isfinite(value):
        raise ValueError(f"{FINISHED_QUERY} must be a finite number, got {raw!r}")
    return value


def _respond(status: http.HTTPStatus, body: bytes, content_type: str) -> Response:
    headers = Headers(
        [
            ("Content-Type", content_type),
            ("Content-Length", str(len(body))),
            ("Cache-Control", "no-store"),
        ]
    )
    return Response(status.value, status.phrase, headers, body)


def serve_page(
    inner: ProcessRequest | None,
    page: str,
    on_finished: Callable[[float], None] | None = None,
) -> ProcessRequest:
    """A ``process_request`` that answers ``GET /`` (no query, no WebSocket upgrade) with
    ``page``, takes the page's reports of finished values (``GET /?finished=VALUE``:
    ``on_finished(VALUE)``, 204; 400 for a value that is not a finite number) and hands every
    other request to ``inner`` (Viser's)."""
    body = page.encode()

    def process_request(
        connection: ServerConnection, request: Request
    ) -> Awaitable[Response | None] | Response | None:
        path, _, query = request.path.partition("?")
        upgrade = request.headers.get("Upgrade", "").lower() == "websocket"
        if path == "/" and not upgrade:
            if not query:
                return _respond(http.HTTPStatus.OK, body, "text/html; charset=utf-8")
            try:
                value = finished_value(query)
            except ValueError as exc:
                return _respond(http.HTTPStatus.BAD_REQUEST, f"{exc}\n".encode(), "text/plain")
            if value is not None:
                if on_finished is not None:
                    on_finished(value)
                return _respond(http.HTTPStatus.NO_CONTENT, b"", "text/plain")
        return inner(connection, request) if inner is not None else None

    return process_request
