"""``spacedg review BENCH_DIR``: a local web page to inspect, filter and correct benchmark items.

The server binds to 127.0.0.1 only and serves one page (``page.html``), the bench's images
and a JSON API over a :class:`~spacedg.review.store.ReviewStore`:

=======================================  ===============================================
``GET  /``                               the page (static; reads the token from its URL)
``GET  /api/items``                      summaries of every item (list and filters)
``GET  /api/items/<index>``              one item: fields, options, images, clean twin,
                                         geometry, history
``POST /api/items/<index>/edit``         ``{"changes": {field: text}}`` → the item, or 400
                                         ``{"error": message}`` (nothing written)
``POST /api/items/<index>/drop``         ``{"dropped": true|false}`` → the item
``GET  /images/<path>``                  an image the bench's rows name (no other file)
=======================================  ===============================================

Every request is treated as hostile (:mod:`spacedg.review.http_guard`): a ``Host`` and
``Origin`` allow-list, a per-start session token (in the URL the command prints, sent by the
page as the ``X-SpaceDG-Token`` header) on everything but the static page, JSON-only POSTs of
bounded size, security headers (CSP, frame denial, nosniff, no referrer) on every response,
and a JSON body ``{"error": message}`` on every error (never a traceback). The reviewer's name
is fixed when the server starts (``--reviewer``); a body cannot set it.

Resources are bounded: one request per connection (HTTP/1.0), at most
:data:`MAX_CONNECTIONS` connections served at once (others get 503 at once), a socket
timeout of :data:`SOCKET_TIMEOUT` seconds per read or write and :data:`REQUEST_DEADLINE`
seconds per connection in all, after which the connection is shut.

Edits go to the store, which writes a new reviewed TSV and an edit log and never touches the
original file; the store holds ``<out>.lock`` while the server runs, so two reviews of one
output cannot interleave.
"""

from __future__ import annotations

import errno
import json
import math
import mimetypes
import re
import socket
import sys
import threading
import time
import traceback
from collections.abc import Sequence
from dataclasses import dataclass
from http import HTTPStatus
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from importlib import resources
from pathlib import Path
from typing import Any
from urllib.parse import parse_qs, unquote, urlsplit

from spacedg.errors import ParameterError, SpaceDGError
from spacedg.review.http_guard import Policy, Refusal, check_json_body, content_security_policy, new_token, security_headers
from spacedg.review.store import ReviewStore

__all__ = ["MAX_CONNECTIONS", "REQUEST_DEADLINE", "SOCKET_TIMEOUT", "ReviewServer", "make_server", "serve_in_thread"]

#: Connections served at once; more are answered 503 and closed.
MAX_CONNECTIONS = 32
#: Seconds a read or write on a connection may block.
SOCKET_TIMEOUT = 10.0
#: Seconds a connection may last in all (a client sending a byte every few seconds is cut off).
REQUEST_DEADLINE = 30.0
#: Longest request path served, characters.
MAX_PATH_CHARS = 2048
#: Largest image file served, bytes.
MAX_IMAGE_BYTES = 64 * 1024 * 1024
_INDEX = re.compile(r"-?[0-9]{1,15}")
_CONTROL = re.compile(r"[\x00-\x1f\x7f]")
_IMAGE_TYPES = ("image/png", "image/jpeg", "image/webp", "image/gif", "image/bmp")


def _page() -> str:
    return resources.files("spacedg.review").joinpath("page.html").read_text(encoding="utf-8")


def _reject_constant(name: str) -> Any:
    raise ValueError(f"{name} is not a JSON number")


def _finite(value: Any) -> Any:
    """``value`` with NaN/±inf floats replaced by ``None`` (JSON has no such numbers)."""
    if isinstance(value, float) and not math.isfinite(value):
        return None
    if isinstance(value, dict):
        return {k: _finite(v) for k, v in value.items()}
    if isinstance(value, (list, tuple)):
        return [_finite(v) for v in value]
    return value


class _Handler(BaseHTTPRequestHandler):
    server: _Server
    protocol_version = "HTTP/1.0"
    server_version = "spacedg-review"
    sys_version = ""
    timeout = SOCKET_TIMEOUT

    def version_string(self) -> str:
        return self.server_version

    def log_message(self, format: str, *args: Any) -> None:  # noqa: A002 - quiet by default
        if self.server.verbose:
            super().log_message(format, *args)

    # ------------------------------------------------------------ responses
    def _send(self, status: int, body: bytes, content_type: str, extra: Sequence[tuple[str, str]] = ()) -> None:
        if self.request_version not in ("HTTP/1.0", "HTTP/1.1"):
            self.request_version = "HTTP/1.0"  # always a status line and headers, whatever the client spoke
        self.close_connection = True
        self._responded = True
        self.send_response(status)
        self.send_header("Content-Type", content_type)
        self.send_header("Content-Length", str(len(body)))
        for name, value in (*self.server.security_headers, *extra):
            self.send_header(name, value)
        self.send_header("Connection", "close")
        self.end_headers()
        if self.command != "HEAD":
            self.wfile.write(body)

    def _json(self, status: int, value: Any, extra: Sequence[tuple[str, str]] = ()) -> None:
        try:
            text = json.dumps(value, allow_nan=False)
        except ValueError:
            text = json.dumps(_finite(value), allow_nan=False)
        self._send(status, text.encode("utf-8"), "application/json; charset=utf-8", extra)

    def _error(self, status: int, message: str, extra: Sequence[tuple[str, str]] = ()) -> None:
        self._json(status, {"error": message}, extra)

    def send_error(self, code: int, message: str | None = None, explain: str | None = None) -> None:
        """The base class's errors (bad request line, header limits, unknown method) as JSON."""
        try:
            phrase = HTTPStatus(code).phrase
        except ValueError:
            phrase = "error"
        self.log_error("code %d, message %s", code, message)
        self._error(code, message or phrase)

    # ------------------------------------------------------------ request handling
    def handle_one_request(self) -> None:
        """The base class's loop step, with a JSON 408 when the request line or headers stall
        (the base class closes silently) and a quiet close when the client vanished."""
        self._responded = False
        try:
            self.raw_requestline = self.rfile.readline(65537)
            if len(self.raw_requestline) > 65536:
                self.requestline = self.request_version = self.command = ""
                self.send_error(HTTPStatus.REQUEST_URI_TOO_LONG, "request line is too long")
                return
            if not self.raw_requestline:
                self.close_connection = True
                return
            if not self.parse_request():
                return
            handler = getattr(self, "do_" + self.command, None)
            if handler is None:
                self.send_error(HTTPStatus.NOT_IMPLEMENTED, f"method {self.command[:20]!r} is not served; use GET or POST")
                return
            handler()
            self.wfile.flush()
        except TimeoutError:
            self.close_connection = True
            if not self._responded:
                try:
                    self._error(HTTPStatus.REQUEST_TIMEOUT, f"the request did not arrive within {self.timeout:g} s")
                except OSError:
                    pass
        except OSError:  # the client went away: nothing to answer
            self.close_connection = True

    def parse_request(self) -> bool:
        if not super().parse_request():
            return False
        if self.request_version == "HTTP/0.9":
            self.send_error(HTTPStatus.BAD_REQUEST, "HTTP/0.9 requests are not served; use HTTP/1.0 or 1.1")
            return False
        return True

    def do_GET(self) -> None:  # noqa: N802 - http.server naming
        self._serve("GET")

    def do_POST(self) -> None:  # noqa: N802
        self._serve("POST")

    def do_HEAD(self) -> None:  # noqa: N802 - checked like any request, then refused (405)
        self._serve(self.command)

    do_PUT = do_DELETE = do_PATCH = do_OPTIONS = do_TRACE = do_CONNECT = do_HEAD  # noqa: N815

    def _serve(self, method: str) -> None:
        try:
            self._route(method)
        except Refusal as refusal:
            allow = [("Allow", "GET, POST")] if refusal.status == HTTPStatus.METHOD_NOT_ALLOWED else []
            self._error(refusal.status, refusal.message, allow)
        except (SpaceDGError, ValueError, KeyError) as err:
            self._error(HTTPStatus.BAD_REQUEST, str(err).strip("'\""))
        except TimeoutError:
            self._error(HTTPStatus.REQUEST_TIMEOUT, f"the request body did not arrive within {self.timeout:g} s")
        except OSError as err:
            if err.errno in (errno.ENOSPC, errno.EDQUOT):
                self._error(HTTPStatus.INSUFFICIENT_STORAGE, f"could not save the change ({err.strerror}: {err.filename or 'the output'}); "
                                                             "nothing was changed: free some disk space and save again")
            else:
                self._error(HTTPStatus.INTERNAL_SERVER_ERROR, f"could not save the change ({err.strerror or type(err).__name__}); "
                                                              "nothing was changed")
        except Exception as err:  # noqa: BLE001 - never a traceback to the client; the terminal gets it
            traceback.print_exc(file=sys.stderr)
            self._error(HTTPStatus.INTERNAL_SERVER_ERROR, f"internal error ({type(err).__name__}); see the terminal running spacedg review")

    def _route(self, method: str) -> None:
        policy = self.server.policy
        policy.check_headers(self.headers)
        if len(self.path) > MAX_PATH_CHARS:
            raise Refusal(HTTPStatus.REQUEST_URI_TOO_LONG, f"request path of {len(self.path)} characters is too long")
        if not self.path.startswith("/"):
            raise Refusal(HTTPStatus.BAD_REQUEST, "request target must be a path starting with /")
        parts = urlsplit(self.path)
        try:
            path = unquote(parts.path, errors="strict")
        except UnicodeDecodeError:
            raise Refusal(HTTPStatus.BAD_REQUEST, "request path is not valid UTF-8 after %-decoding") from None
        if _CONTROL.search(path):
            raise Refusal(HTTPStatus.BAD_REQUEST, "request path holds control characters")
        if method not in ("GET", "POST"):  # a CORS preflight (OPTIONS) of another origin was refused above
            raise Refusal(HTTPStatus.METHOD_NOT_ALLOWED, f"method {method} is not served; use GET or POST")
        if method == "GET" and path in ("/", "/index.html"):
            self._send(HTTPStatus.OK, self.server.page, "text/html; charset=utf-8")
            return
        query = parse_qs(parts.query, keep_blank_values=True, max_num_fields=20) if parts.query else {}
        policy.check_token(self.headers, query, allow_query=method == "GET")
        if method == "GET":
            self._get(path)
        else:
            self._post(path)

    def _get(self, path: str) -> None:
        store = self.server.store
        if path == "/api/items":
            self._json(HTTPStatus.OK, {"items": store.summaries(), "reviewer": self.server.reviewer,
                                       "bench": str(store.table), "out": str(store.out), "log": str(store.log)})
        elif path.startswith("/api/items/") and path.count("/") == 3:
            self._json(HTTPStatus.OK, store.item(self._index(path.rsplit("/", 1)[1])))
        elif path.startswith("/images/"):
            self._image(path[len("/images/"):])
        else:
            raise Refusal(HTTPStatus.NOT_FOUND, f"no such page: {path[:200]}")

    def _post(self, path: str) -> None:
        parts = path.strip("/").split("/")
        if len(parts) != 4 or parts[:2] != ["api", "items"] or parts[3] not in ("edit", "drop"):
            raise Refusal(HTTPStatus.NOT_FOUND, f"no such action: {path[:200]}")
        index = self._index(parts[2])
        body = self._body()
        store, reviewer = self.server.store, self.server.reviewer
        if parts[3] == "edit":
            self._only(body, {"changes"})
            changes = body.get("changes")
            if not isinstance(changes, dict) or not changes or not all(isinstance(v, str) for v in changes.values()):
                raise ValueError('an edit needs {"changes": {field: text, ...}}')
            self._json(HTTPStatus.OK, store.edit(index, changes, reviewer))
        else:
            self._only(body, {"dropped"})
            dropped = body.get("dropped")
            if not isinstance(dropped, bool):
                raise ValueError('a drop needs {"dropped": true} or {"dropped": false}')
            self._json(HTTPStatus.OK, store.set_dropped(index, dropped, reviewer))

    # ------------------------------------------------------------ pieces
    @staticmethod
    def _only(body: dict[str, Any], allowed: set[str]) -> None:
        extra = sorted(set(body) - allowed)
        if "reviewer" in extra:
            raise ValueError("the reviewer is fixed when the server starts (spacedg review --reviewer NAME); "
                             "a request cannot set it")
        if extra:
            raise ValueError(f"unknown field(s) {', '.join(repr(k[:40]) for k in extra[:5])}; "
                             f"send only {', '.join(repr(a) for a in sorted(allowed))}")

    @staticmethod
    def _index(part: str) -> int:
        if not _INDEX.fullmatch(part):
            raise ValueError(f"item index {part[:40]!r} is not an integer")
        return int(part)

    def _body(self) -> dict[str, Any]:
        size = check_json_body(self.headers)
        raw = self.rfile.read(size) if size else b""
        if len(raw) < size:
            raise Refusal(HTTPStatus.BAD_REQUEST, f"request body ended after {len(raw)} of {size} bytes")
        try:
            value = json.loads(raw.decode("utf-8"), parse_constant=_reject_constant)
        except UnicodeDecodeError:
            raise ValueError("request body is not UTF-8 text") from None
        except json.JSONDecodeError as err:
            raise ValueError(f"request body is not JSON ({err.msg})") from None
        except RecursionError:
            raise ValueError("request body is nested too deeply") from None
        if not isinstance(value, dict):
            raise ValueError("request body must be a JSON object")
        return value

    def _image(self, rel: str) -> None:
        target = self.server.images.get(rel)
        if target is None:
            raise Refusal(HTTPStatus.NOT_FOUND, f"no image {rel[:200]!r} in the bench")
        kind = mimetypes.guess_type(target.name)[0] or ""
        try:
            size = target.stat().st_size
            if size > MAX_IMAGE_BYTES:
                raise Refusal(HTTPStatus.NOT_FOUND, f"image {rel[:200]!r} is over {MAX_IMAGE_BYTES} bytes")
            data = target.read_bytes()
        except OSError:
            raise Refusal(HTTPStatus.NOT_FOUND, f"image {rel[:200]!r} is missing or unreadable") from None
        self._send(HTTPStatus.OK, data, kind)


class _Server(ThreadingHTTPServer):
    """A threading HTTP server with at most :data:`MAX_CONNECTIONS` connections at once and a
    deadline per connection."""

    daemon_threads = True
    request_queue_size = 64

    def __init__(self, address: tuple[str, int], token: str, verbose: bool) -> None:
        super().__init__(address, _Handler)
        self.verbose = verbose
        self.policy = Policy(int(self.server_address[1]), token)
        page = _page()
        self.page = page.encode("utf-8")
        self.security_headers = security_headers(content_security_policy(page))
        self.store: ReviewStore | None = None  # set by make_server once the socket is bound
        self.reviewer = ""
        self.images: dict[str, Path] = {}
        self._slots = threading.BoundedSemaphore(MAX_CONNECTIONS)
        self._active: dict[socket.socket, float] = {}
        self._active_lock = threading.Lock()
        self._stop = threading.Event()
        self._reaper = threading.Thread(target=self._reap, name="spacedg-review-reaper", daemon=True)
        self._reaper.start()

    def attach(self, store: ReviewStore, reviewer: str) -> None:
        """Serve ``store``; only the images its rows name, inside its folder, are reachable."""
        self.store = store
        self.reviewer = reviewer
        root = store.root.resolve()
        images: dict[str, Path] = {}
        for rel in store.referenced_images():
            if _CONTROL.search(rel) or (mimetypes.guess_type(rel)[0] or "") not in _IMAGE_TYPES:
                continue
            try:
                target = (root / rel).resolve()
                target.relative_to(root)
            except (OSError, ValueError, RuntimeError):
                continue  # outside the bench folder (or unresolvable): never served
            images[rel] = target
        self.images = images

    # ------------------------------------------------------------ bounded connections
    def process_request(self, request: Any, client_address: Any) -> None:
        if not self._slots.acquire(blocking=False):
            self._busy(request)
            return
        try:
            super().process_request(request, client_address)
        except BaseException:
            self._slots.release()
            raise

    def process_request_thread(self, request: Any, client_address: Any) -> None:
        with self._active_lock:
            self._active[request] = time.monotonic()
        try:
            super().process_request_thread(request, client_address)
        finally:
            with self._active_lock:
                self._active.pop(request, None)
            self._slots.release()

    def _busy(self, request: socket.socket) -> None:
        body = json.dumps({"error": f"the review server is busy ({MAX_CONNECTIONS} connections open); try again"}).encode()
        head = ["HTTP/1.0 503 Service Unavailable", "Content-Type: application/json; charset=utf-8",
                f"Content-Length: {len(body)}", "Connection: close", "Retry-After: 1",
                *(f"{k}: {v}" for k, v in self.security_headers)]
        try:
            request.settimeout(0.2)
            request.sendall(("\r\n".join(head) + "\r\n\r\n").encode("latin-1") + body)
        except OSError:
            pass
        finally:
            self.shutdown_request(request)

    def _reap(self) -> None:
        """Shut connections older than :data:`REQUEST_DEADLINE` (their reads then end)."""
        while not self._stop.wait(0.5):
            now = time.monotonic()
            with self._active_lock:
                late = [s for s, started in self._active.items() if now - started > REQUEST_DEADLINE]
            for sock in late:
                try:
                    sock.shutdown(socket.SHUT_RDWR)
                except OSError:
                    pass

    def handle_error(self, request: Any, client_address: Any) -> None:
        """A connection that failed outside a route (the client vanished mid-response): one line
        with ``--verbose``, nothing otherwise (never a traceback)."""
        if self.verbose:
            err = sys.exc_info()[1]
            print(f"review: connection from {client_address[0]} failed: {type(err).__name__}: {err}", file=sys.stderr)

    def server_close(self) -> None:
        self._stop.set()
        super().server_close()


@dataclass
class ReviewServer:
    """A running review server.

    Attributes:
        url: the address to open, with the session token (``http://127.0.0.1:PORT/?token=…``).
        base_url: the address without the token.
        token: the session token.
        store: the :class:`ReviewStore` served.
        httpd: the HTTP server; ``close()`` stops it and frees the store's lock.
    """

    url: str
    base_url: str
    token: str
    store: ReviewStore
    httpd: _Server
    thread: threading.Thread | None = None

    def start(self) -> None:
        """Serve on a background thread (:meth:`close` stops it)."""
        self.thread = threading.Thread(target=self.httpd.serve_forever, kwargs={"poll_interval": 0.1}, name="spacedg-review", daemon=True)
        self.thread.start()

    def close(self) -> None:
        if self.thread is not None:
            self.httpd.shutdown()
        self.httpd.server_close()
        if self.thread is not None:
            self.thread.join(timeout=5)
        self.store.close()


def check_port(port: Any) -> int:
    """``port`` as an int in [0, 65535] (0: any free port), or :class:`ParameterError`."""
    if isinstance(port, bool) or not isinstance(port, int) or not 0 <= port <= 65535:
        raise ParameterError(f"--port must be a whole number from 0 to 65535 (0 = any free port), got {port!r}")
    return port


def check_reviewer(reviewer: Any) -> str:
    """The reviewer name recorded in the log: one line of 1–100 printable characters."""
    if not isinstance(reviewer, str) or not reviewer.strip():
        raise ParameterError("--reviewer must be a non-empty name (it is recorded in the edit log)")
    name = reviewer.strip()
    if len(name) > 100 or not name.isprintable():
        raise ParameterError(f"--reviewer {name[:40]!r}…: use one line of at most 100 printable characters")
    return name


def make_server(bench: str | Path, *, out: str | Path | None = None, reviewer: str = "reviewer",
                scenes: Sequence[str | Path] | None = None, port: int = 8765, verbose: bool = False,
                token: str | None = None) -> ReviewServer:
    """Bind ``127.0.0.1:port`` (``port=0``: any free port), then open the bench (and take its
    output's lock). Nothing is written before the port and the reviewer name are known good."""
    port = check_port(port)
    reviewer = check_reviewer(reviewer)
    token = token or new_token()
    try:
        httpd = _Server(("127.0.0.1", port), token, verbose)
    except OSError as err:
        raise SpaceDGError(f"cannot listen on 127.0.0.1:{port} ({err.strerror}); pick another --port") from None
    try:
        store = ReviewStore(bench, out=out, scenes=scenes, lock=True)
        httpd.attach(store, reviewer)
    except BaseException:
        httpd.server_close()
        raise
    base = f"http://127.0.0.1:{httpd.server_address[1]}/"
    return ReviewServer(f"{base}?token={token}", base, token, store, httpd)


def serve_in_thread(bench: str | Path, *, out: str | Path | None = None, reviewer: str = "reviewer",
                    scenes: Sequence[str | Path] | None = None, port: int = 0, token: str | None = None) -> ReviewServer:
    """:func:`make_server` running on a background thread (tests, notebooks)."""
    server = make_server(bench, out=out, reviewer=reviewer, scenes=scenes, port=port, token=token)
    server.start()
    return server
