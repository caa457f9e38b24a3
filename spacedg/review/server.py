"""``spacedg review BENCH_DIR``: a local web page to inspect, filter and correct benchmark items.

The server binds to 127.0.0.1 only and serves one page (``page.html``) plus a JSON API over a
:class:`~spacedg.review.store.ReviewStore`:

=======================================  ===============================================
``GET  /``                               the page
``GET  /api/items``                      summaries of every item (list and filters)
``GET  /api/items/<index>``              one item: fields, options, images, clean twin,
                                         geometry, history
``POST /api/items/<index>/edit``         ``{"changes": {field: text}}`` → the item, or 400
                                         ``{"error": message}`` (nothing written)
``POST /api/items/<index>/drop``         ``{"dropped": true|false}`` → the item
``GET  /images/<path>``                  an image of the bench (paths inside it only)
=======================================  ===============================================

Edits go to the store, which writes a new reviewed TSV and an edit log and never touches the
original file. Requests are served on threads; the store serialises writes.
"""

from __future__ import annotations

import json
import mimetypes
import threading
from collections.abc import Sequence
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import unquote, urlparse

from spacedg.errors import SpaceDGError
from spacedg.review.store import ReviewStore

__all__ = ["ReviewServer", "make_server", "serve_in_thread"]

_MAX_BODY = 1 << 20  # bytes of a POST body


def _page() -> bytes:
    return resources.files("spacedg.review").joinpath("page.html").read_bytes()


class _Handler(BaseHTTPRequestHandler):
    server: _Server

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - quiet by default
        if self.server.verbose:
            super().log_message(format, *args)

    # ------------------------------------------------------------ helpers
    def _send(self, status: int, body: bytes, content_type: str) -> None:
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        self.send_header("Cache-Control", "no-store")
        self.end_headers()
        self.wfile.write(body)

    def _json(self, status: int, value: Any) -> None:
        self._send(status, json.dumps(value).encode(), "application/json; charset=utf-8")

    def _error(self, status: int, message: str) -> None:
        self._json(status, {"error": message})

    def _body(self) -> dict[str, Any]:
        length = int(self.headers.get("Content-Length") or 0)
        if length > _MAX_BODY:
            raise ValueError(f"request body of {length} bytes is too large")
        raw = self.rfile.read(length) if length else b"{}"
        try:
            value = json.loads(raw or b"{}")
        except json.JSONDecodeError as err:
            raise ValueError(f"request body is not JSON ({err.msg})") from None
        if not isinstance(value, dict):
            raise ValueError("request body must be a JSON object")
        return value

    def _index(self, part: str) -> int:
        try:
            return int(part)
        except ValueError:
            raise ValueError(f"item index {part!r} is not an integer") from None

    # ------------------------------------------------------------ routes
    def do_GET(self) -> None:  # noqa: N802 - http.server naming
        path = unquote(urlparse(self.path).path)
        store = self.server.store
        try:
            if path in ("/", "/index.html"):
                self._send(HTTPStatus.OK, _page(), "text/html; charset=utf-8")
            elif path == "/api/items":
                self._json(HTTPStatus.OK, {"items": store.summaries(), "reviewer": self.server.reviewer,
                                           "bench": str(store.table), "out": str(store.out), "log": str(store.log)})
            elif path.startswith("/api/items/"):
                self._json(HTTPStatus.OK, store.item(self._index(path.split("/")[3])))
            elif path.startswith("/images/"):
                self._image(path[len("/images/"):])
            else:
                self._error(HTTPStatus.NOT_FOUND, f"no such page: {path}")
        except (SpaceDGError, ValueError, KeyError) as err:
            self._error(HTTPStatus.BAD_REQUEST, str(err).strip("'\""))

    def do_POST(self) -> None:  # noqa: N802
        path = unquote(urlparse(self.path).path)
        store = self.server.store
        parts = path.strip("/").split("/")
        try:
            if len(parts) != 4 or parts[:2] != ["api", "items"] or parts[3] not in ("edit", "drop"):
                self._error(HTTPStatus.NOT_FOUND, f"no such action: {path}")
                return
            index = self._index(parts[2])
            body = self._body()
            reviewer = str(body.get("reviewer") or self.server.reviewer)
            if parts[3] == "edit":
                changes = body.get("changes")
                if not isinstance(changes, dict) or not all(isinstance(v, str) for v in changes.values()):
                    raise ValueError('an edit needs {"changes": {field: text, ...}}')
                self._json(HTTPStatus.OK, store.edit(index, changes, reviewer))
            else:
                dropped = body.get("dropped")
                if not isinstance(dropped, bool):
                    raise ValueError('a drop needs {"dropped": true} or {"dropped": false}')
                self._json(HTTPStatus.OK, store.set_dropped(index, dropped, reviewer))
        except (SpaceDGError, ValueError, KeyError) as err:
            self._error(HTTPStatus.BAD_REQUEST, str(err).strip("'\""))

    def _image(self, rel: str) -> None:
        root = self.server.image_root.resolve()
        target = (root / rel).resolve()
        if root not in target.parents or not target.is_file():
            self._error(HTTPStatus.NOT_FOUND, f"no image {rel!r} in the bench")
            return
        kind = mimetypes.guess_type(target.name)[0] or "application/octet-stream"
        self._send(HTTPStatus.OK, target.read_bytes(), kind)


class _Server(ThreadingHTTPServer):
    daemon_threads = True

    def __init__(self, address: tuple[str, int], store: ReviewStore, reviewer: str, verbose: bool) -> None:
        super().__init__(address, _Handler)
        self.store = store
        self.reviewer = reviewer
        self.verbose = verbose
        self.image_root = store.table.parent


@dataclass
class ReviewServer:
    """A running review server: ``url``, its ``store``; ``close()`` stops it."""

    url: str
    store: ReviewStore
    httpd: _Server
    thread: threading.Thread | None = None

    def close(self) -> None:
        self.httpd.shutdown()
        self.httpd.server_close()
        if self.thread is not None:
            self.thread.join(timeout=5)


def make_server(bench: str | Path, *, out: str | Path | None = None, reviewer: str = "reviewer",
                scenes: Sequence[str | Path] | None = None, port: int = 8765, verbose: bool = False) -> ReviewServer:
    """Open the bench and bind the server to ``127.0.0.1:port`` (``port=0``: any free port)."""
    store = ReviewStore(bench, out=out, scenes=scenes)
    try:
        httpd = _Server(("127.0.0.1", int(port)), store, reviewer, verbose)
    except OSError as err:
        raise SpaceDGError(f"cannot listen on 127.0.0.1:{port} ({err.strerror}); pick another --port") from None
    return ReviewServer(f"http://127.0.0.1:{httpd.server_address[1]}/", store, httpd)


def serve_in_thread(bench: str | Path, *, out: str | Path | None = None, reviewer: str = "reviewer",
                    scenes: Sequence[str | Path] | None = None, port: int = 0) -> ReviewServer:
    """:func:`make_server` running on a background thread (tests, notebooks)."""
    server = make_server(bench, out=out, reviewer=reviewer, scenes=scenes, port=port)
    server.thread = threading.Thread(target=server.httpd.serve_forever, name="spacedg-review", daemon=True)
    server.thread.start()
    return server
