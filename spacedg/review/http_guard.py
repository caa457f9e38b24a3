"""Who may talk to the review server, and what every response carries: pure checks, no sockets.

The review server treats every request as hostile. A request is served only when

1. it has exactly one ``Host`` header naming this server (``127.0.0.1:<port>`` or
   ``localhost:<port>``): a DNS-rebinding page reaches the socket under its own host name and is
   refused, so it can read nothing;
2. its ``Origin`` (when sent; browsers send it on every POST) is this server's own origin, and
   its ``Sec-Fetch-Site`` (when sent) is ``same-origin`` or ``none``: a page of any other origin,
   another port of 127.0.0.1 included, is refused before any routing;
3. (everything but the static page itself) it carries the session token: the
   ``X-SpaceDG-Token`` header, or for a ``GET`` also a ``token`` query parameter (how ``<img>``
   sends it). The token is random per server start and shown only in the URL that
   ``spacedg review`` prints (like Jupyter); a POST must send it as the header, which a plain
   HTML form cannot and a cross-origin ``fetch`` can only after a CORS preflight that is refused;
4. (POST) its body is declared ``Content-Type: application/json`` (UTF-8) with a
   ``Content-Length`` of at most :data:`MAX_BODY_BYTES`.

Every response carries :func:`security_headers`: a Content-Security-Policy that allows only
this page's own script and style (by hash) and same-origin images and fetches and forbids
framing, ``X-Frame-Options: DENY``, ``X-Content-Type-Options: nosniff``,
``Referrer-Policy: no-referrer``, ``Cross-Origin-Resource-Policy: same-origin``,
``Cross-Origin-Opener-Policy: same-origin`` and ``Cache-Control: no-store``. No response
carries CORS headers.
"""

from __future__ import annotations

import base64
import hashlib
import hmac
import re
import secrets
from collections.abc import Iterable, Mapping
from dataclasses import dataclass, field
from email.message import Message

__all__ = [
    "MAX_BODY_BYTES",
    "TOKEN_HEADER",
    "Refusal",
    "Policy",
    "check_json_body",
    "content_security_policy",
    "new_token",
    "security_headers",
]

#: Largest POST body accepted, bytes (an edit is a few hundred).
MAX_BODY_BYTES = 256 * 1024
#: The request header that carries the session token.
TOKEN_HEADER = "X-SpaceDG-Token"
_CONTENT_LENGTH = re.compile(r"[0-9]{1,10}")
_SINGLE = ("Host", "Origin", "Content-Length", "Content-Type", TOKEN_HEADER, "Sec-Fetch-Site", "Transfer-Encoding")


class Refusal(Exception):
    """A request refused before it reaches a route: ``status`` and a message for the JSON body."""

    def __init__(self, status: int, message: str) -> None:
        super().__init__(message)
        self.status = status
        self.message = message


def new_token() -> str:
    """A fresh session token (32 random bytes, URL-safe text)."""
    return secrets.token_urlsafe(32)


def _hash_source(text: str) -> str:
    return "'sha256-" + base64.b64encode(hashlib.sha256(text.encode("utf-8")).digest()).decode("ascii") + "'"


def content_security_policy(page: str) -> str:
    """The CSP of every response: the inline ``<script>``/``<style>`` blocks of ``page`` by hash,
    images and fetches from this origin only, no plugins, frames, forms or base URI changes."""
    scripts = [_hash_source(m) for m in re.findall(r"<script>(.*?)</script>", page, flags=re.S)]
    styles = [_hash_source(m) for m in re.findall(r"<style>(.*?)</style>", page, flags=re.S)]
    return "; ".join([
        "default-src 'none'",
        "script-src " + (" ".join(scripts) or "'none'"),
        "style-src " + (" ".join(styles) or "'none'"),
        "img-src 'self'",
        "connect-src 'self'",
        "base-uri 'none'",
        "form-action 'none'",
        "frame-ancestors 'none'",
    ])


def security_headers(csp: str) -> list[tuple[str, str]]:
    """The headers every response carries (see the module docstring)."""
    return [
        ("Content-Security-Policy", csp),
        ("X-Frame-Options", "DENY"),
        ("X-Content-Type-Options", "nosniff"),
        ("Referrer-Policy", "no-referrer"),
        ("Cross-Origin-Resource-Policy", "same-origin"),
        ("Cross-Origin-Opener-Policy", "same-origin"),
        ("Cache-Control", "no-store"),
    ]


@dataclass
class Policy:
    """The allow-lists of one server: its port and token.

    Attributes:
        port: the bound port.
        token: the session token.
        hosts: accepted ``Host`` values (``127.0.0.1:<port>``, ``localhost:<port>``).
        origins: accepted ``Origin`` values (``http://`` + each host).
    """

    port: int
    token: str
    hosts: frozenset[str] = field(init=False)
    origins: frozenset[str] = field(init=False)

    def __post_init__(self) -> None:
        self.hosts = frozenset({f"127.0.0.1:{self.port}", f"localhost:{self.port}"})
        self.origins = frozenset(f"http://{h}" for h in self.hosts)

    def check_headers(self, headers: Message) -> None:
        """Refuse duplicated security headers, a foreign ``Host``, ``Origin`` or ``Sec-Fetch-Site``."""
        for name in _SINGLE:
            if len(headers.get_all(name, [])) > 1:
                raise Refusal(400, f"the {name} header appears more than once")
        host = (headers.get("Host") or "").strip().lower()
        if host not in self.hosts:
            shown = host[:80] or "none"
            raise Refusal(403, f"Host {shown!r} is not this server; open http://127.0.0.1:{self.port}/ (the address spacedg review printed)")
        origin = headers.get("Origin")
        if origin is not None and origin.strip().lower() not in self.origins:
            raise Refusal(403, f"requests from origin {origin.strip()[:80]!r} are refused; only this page may use the review server")
        site = headers.get("Sec-Fetch-Site")
        if site is not None and site.strip().lower() not in ("same-origin", "none"):
            raise Refusal(403, f"a {site.strip()[:20]!r} request is refused; only this page may use the review server")

    def check_token(self, headers: Message, query: Mapping[str, Iterable[str]], *, allow_query: bool) -> None:
        """Refuse a request without this server's token (header, or ``token`` query for GETs)."""
        given = headers.get(TOKEN_HEADER)
        if given is None and allow_query:
            values = list(query.get("token", ()))
            given = values[0] if len(values) == 1 else None
        if given is None or not hmac.compare_digest(given.encode("utf-8", "replace"), self.token.encode("utf-8")):
            what = "a wrong" if given is not None else "no"
            raise Refusal(403, f"{what} session token; open the address spacedg review printed (it ends with ?token=…)")


def check_json_body(headers: Message) -> int:
    """The declared length of a JSON POST body, or :class:`Refusal` (415, 411, 400, 413, 501)."""
    if headers.get("Transfer-Encoding") is not None:
        raise Refusal(501, "Transfer-Encoding bodies are not accepted; send the JSON with a Content-Length")
    kind = headers.get("Content-Type")
    media, _, params = (kind or "").partition(";")
    if media.strip().lower() != "application/json":
        raise Refusal(415, f"Content-Type {(kind or 'none')[:60]!r} is refused; send application/json")
    charset = params.strip().lower()
    if charset and charset.replace(" ", "") not in ("charset=utf-8", 'charset="utf-8"'):
        raise Refusal(415, f"Content-Type parameters {params.strip()[:40]!r} are refused; send UTF-8 JSON")
    length = headers.get("Content-Length")
    if length is None:
        raise Refusal(411, "a POST needs a Content-Length")
    if not _CONTENT_LENGTH.fullmatch(length.strip()):
        raise Refusal(400, f"Content-Length {length.strip()[:20]!r} is not a byte count")
    size = int(length.strip())
    if size > MAX_BODY_BYTES:
        raise Refusal(413, f"request body of {size} bytes is over the {MAX_BODY_BYTES}-byte limit")
    return size
