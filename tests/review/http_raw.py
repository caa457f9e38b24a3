"""A raw-socket HTTP client for the review server tests: sends exactly the bytes given (hostile
requests included) and parses whatever comes back, with timeouts everywhere."""

from __future__ import annotations

import json
import socket
import time
from dataclasses import dataclass, field
from typing import Any

SECURITY_HEADERS = {
    "content-security-policy", "x-frame-options", "x-content-type-options", "referrer-policy",
    "cross-origin-resource-policy", "cache-control",
}


@dataclass
class Response:
    """A parsed response: ``status`` (0: the connection closed with no response), headers
    (lower-case name → values), body, the seconds it took."""

    status: int
    headers: dict[str, list[str]] = field(default_factory=dict)
    body: bytes = b""
    seconds: float = 0.0
    raw: bytes = b""

    def header(self, name: str) -> str | None:
        values = self.headers.get(name.lower())
        return values[0] if values else None

    def json(self) -> Any:
        return json.loads(self.body)


def parse(raw: bytes) -> Response:
    head, sep, body = raw.partition(b"\r\n\r\n")
    if not sep:
        return Response(0, raw=raw)
    lines = head.decode("latin-1").split("\r\n")
    parts = lines[0].split(" ", 2)
    status = int(parts[1]) if len(parts) >= 2 and parts[0].startswith("HTTP/") and parts[1].isdigit() else 0
    headers: dict[str, list[str]] = {}
    for line in lines[1:]:
        name, _, value = line.partition(":")
        headers.setdefault(name.strip().lower(), []).append(value.strip())
    return Response(status, headers, body, raw=raw)


def send(port: int, data: bytes, *, timeout: float = 15.0, half_close: bool = True) -> Response:
    """Send ``data`` to 127.0.0.1:``port`` and read until the server closes (or ``timeout``).
    ``half_close``: shut our writing side after sending (a short body then ends at once)."""
    started = time.monotonic()
    with socket.create_connection(("127.0.0.1", port), timeout=timeout) as sock:
        try:
            sock.sendall(data)
            if half_close:
                sock.shutdown(socket.SHUT_WR)
        except OSError:
            pass
        chunks = []
        deadline = started + timeout
        while time.monotonic() < deadline:
            try:
                chunk = sock.recv(65536)
            except OSError:  # a timeout included
                break
            if not chunk:
                break
            chunks.append(chunk)
    response = parse(b"".join(chunks))
    response.seconds = time.monotonic() - started
    return response


def request(port: int, method: str, path: str, *, headers: dict[str, str] | None = None, body: bytes | None = None,
            host: str | None = None, **kwargs: Any) -> Response:
    """A well-formed HTTP/1.1 request (``Host`` = this server unless given; ``Content-Length``
    added for a body unless given)."""
    lines = [f"{method} {path} HTTP/1.1", f"Host: {host if host is not None else f'127.0.0.1:{port}'}"]
    given = {k.lower() for k in (headers or {})}
    for name, value in (headers or {}).items():
        lines.append(f"{name}: {value}")
    if body is not None and "content-length" not in given:
        lines.append(f"Content-Length: {len(body)}")
    data = ("\r\n".join(lines) + "\r\n\r\n").encode("latin-1") + (body or b"")
    return send(port, data, **kwargs)
