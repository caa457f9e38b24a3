"""A seeded fuzz of the review server's HTTP surface: a few hundred hostile requests (random
methods, versions, headers, paths, bodies and lengths, some with the real token and a valid
payload). Every request gets a well-formed response within the timeout, carrying the security
headers, as JSON (or the page, or an image); never a 500 or a traceback; and the store changes
only through valid authenticated requests, with the reviewed TSV matching its log."""

from __future__ import annotations

import json
import random
from collections import Counter
from collections.abc import Callable
from pathlib import Path

import cv2
import numpy as np
import pytest

from spacedg.review import server as server_module
from spacedg.review import ReviewStore
from spacedg.review.server import serve_in_thread
from tests.eval_fixtures import write_bench
from tests.review.http_raw import SECURITY_HEADERS, send

SEED = 20260420
REQUESTS = 600
TOKEN = "fuzz-token-" + "k" * 32
METHODS = ["GET", "GET", "GET", "POST", "POST", "POST", "HEAD", "PUT", "DELETE", "OPTIONS", "PATCH", "TRACE", "CONNECT",
           "get", "G\x00T", "POST /x", "", "BREW", "GET" * 200]
VERSIONS = ["HTTP/1.1"] * 6 + ["HTTP/1.0"] * 2 + ["", "HTTP/2.0", "HTTP/1.1x", "HTTP/0.9", "http/1.1", "HTTP/1.1 extra"]
PATHS = ["/", "/index.html", "/api/items", "/api/items/0", "/api/items/3", "/api/items/14", "/api/items/15", "/api/items/-1",
         "/api/items/0/edit", "/api/items/5/edit", "/api/items/7/drop", "/api/items/x/edit", "/api/items/0/explode",
         "/images/images/0000000_0.png", "/images/images/0000009_0.png", "/images/.ssh/id_rsa", "/images/../bench.tsv",
         "/images/%2e%2e/%2e%2e/etc/passwd", "/images/" + "a/" * 3000, "/%ff%fe", "/api/items/%00", "//api/items", "*",
         "http://attacker.example/api/items", "/api/items/0/edit?token=" + TOKEN, "/api/items?token=" + TOKEN,
         "/api/items?token=wrong", "/api/items?" + "&".join(f"k{i}=v" for i in range(40)), "/favicon.ico",
         "/api/items/" + "9" * 30, "/\u00e9t\u00e9", "/api/items/1/edit/extra"]
CONTENT_TYPES = ["application/json", "application/json", "application/json; charset=utf-8", "text/plain",
                 "application/x-www-form-urlencoded", "multipart/form-data; boundary=zz", "application/json; charset=utf-16",
                 "APPLICATION/JSON", "", "application/jsonx"]
ORIGINS = [None, None, None, "own", "http://evil.example", "null", "http://127.0.0.1:1", "http://localhost:PORT", "own"]


def _body(rng: random.Random) -> bytes:
    kind = rng.randrange(12)
    if kind == 0:
        return json.dumps({"changes": {"answer": rng.choice(["A", "B", "C", "D", "E", "yes", "no", "3", "2.5", "[1, 2, 3]"])}}).encode()
    if kind == 1:
        return json.dumps({"dropped": rng.choice([True, False, "yes", 1, None])}).encode()
    if kind == 2:
        return json.dumps({"changes": {rng.choice(["question", "A", "B", "colour", "index"]): rng.choice(["x", "", "a\nb", 3])}}).encode()
    if kind == 3:
        return json.dumps({"changes": {"answer": "C"}, "reviewer": "mallory"}).encode()
    if kind == 4:
        depth = rng.choice([10, 1000, 60_000])
        return b"[" * depth + b"]" * depth
    if kind == 5:
        return bytes(rng.getrandbits(8) for _ in range(rng.randrange(0, 300)))
    if kind == 6:
        return b'{"changes": {"answer": NaN}}'
    if kind == 7:
        return b""
    if kind == 8:
        return json.dumps([{"changes": {}}]).encode()
    if kind == 9:
        return b'{"changes": {"answer": "' + b"z" * rng.choice([10, 5000, 300_000]) + b'"}}'
    if kind == 10:
        return "{\"changes\": {\"question\": \"\u00e9\u2603\ud83d\ude00 \\u0000\"}}".encode("utf-8", "surrogatepass")
    return b'{"changes": {"answer": "A"}, "dropped": true}'


NEAR_VALID = [
    "/api/items", "/api/items/0", "/api/items/7", "/api/items/14", "/images/images/0000004_0.png",
    "/api/items/0/edit", "/api/items/5/edit", "/api/items/8/edit", "/api/items/3/drop", "/api/items/11/drop",
]


def _near_valid(rng: random.Random, port: int) -> tuple[bytes, dict]:
    """A request a real page could send (one of the routes, token, JSON) with a random payload."""
    path = rng.choice(NEAR_VALID)
    method = "POST" if path.endswith(("edit", "drop")) else "GET"
    body = _body(rng) if method == "POST" else b""
    if method == "POST" and rng.random() < 0.5:
        body = json.dumps({"dropped": rng.choice([True, False])} if path.endswith("drop")
                          else {"changes": {"answer": rng.choice(["A", "B", "C", "D", "yes", "no", "4", "2.5", "[1, 2, 3]"])}}).encode()
    headers = [f"Host: 127.0.0.1:{port}", f"X-SpaceDG-Token: {TOKEN}", "Content-Type: application/json", f"Content-Length: {len(body)}"]
    if rng.random() < 0.5:
        headers.append(f"Origin: http://127.0.0.1:{port}")
    raw = (f"{method} {path} HTTP/1.1\r\n" + "".join(h + "\r\n" for h in headers) + "\r\n").encode() + body
    return raw, {"method": method, "path": path, "version": "HTTP/1.1", "headers": headers, "body": body, "raw": raw}


def _pick(rng: random.Random, cases: list[tuple[float, Callable[[], list[str]]]]) -> list[str]:
    """The headers of the first case whose cumulative probability ``upto`` exceeds one uniform draw
    (none past the last): ``cases`` = [(upto, make headers), …] in increasing ``upto``."""
    draw = rng.random()
    return next((make() for upto, make in cases if draw < upto), [])


def _request(rng: random.Random, port: int) -> tuple[bytes, dict]:
    """One hostile request and what it claims (to tell valid authenticated writes apart)."""
    if rng.random() < 0.35:
        return _near_valid(rng, port)
    method = rng.choice(METHODS)
    path = rng.choice(PATHS)
    version = rng.choice(VERSIONS)
    line = " ".join(p for p in (method, path, version) if p)
    headers: list[str] = []
    headers += _pick(rng, [
        (0.75, lambda: [f"Host: 127.0.0.1:{port}"]),
        (0.8, lambda: [f"Host: localhost:{port}"]),
        (0.9, lambda: [rng.choice(["Host: attacker.example", f"Host: attacker.example:{port}", "Host:", f"Host: 127.0.0.1:{port + 1}"])]),
        (0.95, lambda: [f"Host: 127.0.0.1:{port}", "Host: attacker.example"]),
    ])
    origin = rng.choice(ORIGINS)
    if origin is not None:
        headers.append("Origin: " + (f"http://127.0.0.1:{port}" if origin == "own" else origin.replace("PORT", str(port))))
    headers += _pick(rng, [
        (0.5, lambda: [f"X-SpaceDG-Token: {TOKEN}"]),
        (0.7, lambda: [f"X-SpaceDG-Token: {rng.choice(['', 'wrong', TOKEN + 'x', TOKEN[:-1], TOKEN.upper()])}"]),
        (0.75, lambda: [f"X-SpaceDG-Token: {TOKEN}", "X-SpaceDG-Token: other"]),
    ])
    if rng.random() < 0.7:
        headers.append("Content-Type: " + rng.choice(CONTENT_TYPES))
    if rng.random() < 0.2:
        headers.append("Sec-Fetch-Site: " + rng.choice(["same-origin", "same-site", "cross-site", "none", "weird"]))
    body = _body(rng) if rng.random() < 0.8 else b""
    bad_lengths = ["-1", "abc", "99999999999", "1e3", " 5", "0x10", str(len(body) + 50), str(max(len(body) - 3, 0)), "",
                   "18446744073709551617"]
    headers += _pick(rng, [
        (0.7, lambda: [f"Content-Length: {len(body)}"]),
        (0.9, lambda: ["Content-Length: " + rng.choice(bad_lengths)]),
        (0.95, lambda: [f"Content-Length: {len(body)}", "Content-Length: 0"]),
    ])
    if rng.random() < 0.1:
        headers.append("Transfer-Encoding: chunked")
    for _ in range(rng.choice([0, 0, 0, 1, 3, 150])):
        headers.append(rng.choice(["X-Junk: " + "j" * rng.choice([5, 70_000]), "no colon here", "X-\u00e9: v", ": empty name",
                                   "Expect: 100-continue", "Connection: keep-alive", "Accept: */*"]))
    head = line + "\r\n" + "".join(h + "\r\n" for h in headers) + "\r\n"
    raw = head.encode("utf-8", "surrogatepass") + body
    if rng.random() < 0.03:
        raw = raw[: rng.randrange(0, len(raw) + 1)]  # cut anywhere, even before the request line ends
    claims = {"method": method, "path": path, "version": version, "headers": headers, "body": body, "raw": raw}
    return raw, claims


def _authenticated_write(claims: dict, port: int) -> bool:
    """True when a request could legitimately write: a POST with the real token header (once),
    this server as its only Host, no foreign Origin or Sec-Fetch-Site, and JSON."""
    headers = claims["headers"]
    if claims["method"] != "POST" or not claims["path"].startswith("/api/items/"):
        return False
    if [h for h in headers if h.startswith("X-SpaceDG-Token:")] != [f"X-SpaceDG-Token: {TOKEN}"]:
        return False
    hosts = [h for h in headers if h.startswith("Host:")]
    return len(hosts) == 1 and hosts[0] in (f"Host: 127.0.0.1:{port}", f"Host: localhost:{port}")


@pytest.fixture()
def served(tmp_path: Path, monkeypatch: pytest.MonkeyPatch):
    monkeypatch.setattr(server_module._Handler, "timeout", 1.0)  # a request whose body never comes: 408 after 1 s
    bench = write_bench(tmp_path / "bench")
    (bench / "images").mkdir()
    for index in range(15):
        cv2.imwrite(str(bench / "images" / f"{index:07d}_0.png"), np.full((8, 8, 3), index, np.uint8))
    (bench / ".ssh").mkdir()
    (bench / ".ssh" / "id_rsa").write_text("PRIVATE KEY")
    running = serve_in_thread(bench, reviewer="fuzz-reviewer", token=TOKEN)
    yield running
    running.close()


def test_fuzz_http_surface(served) -> None:
    port = int(served.httpd.server_address[1])
    rng = random.Random(SEED)
    original_out, table = served.store.out.read_bytes(), served.store.table.read_bytes()
    statuses: Counter[int] = Counter()
    writes_ok = 0
    for number in range(REQUESTS):
        raw, claims = _request(rng, port)
        response = send(port, raw, timeout=8, half_close=rng.random() > 0.02)
        where = f"request {number}: {raw[:160]!r}"
        statuses[response.status] += 1
        assert response.seconds < 6, f"{where}: took {response.seconds:.1f} s"
        if response.status == 0:  # only an empty connection goes unanswered
            assert raw == b"", f"{where}: no response"
            continue
        assert response.status != 500 and response.status < 600, f"{where}: {response.raw[:300]!r}"
        assert SECURITY_HEADERS <= set(response.headers), f"{where}: headers {sorted(response.headers)}"
        assert "access-control-allow-origin" not in response.headers
        assert b"Traceback" not in response.body and b"PRIVATE KEY" not in response.body
        kind = response.header("content-type") or ""
        if response.status == 200 and kind.startswith("text/html"):
            assert claims["method"] == "GET" and b'id="item-list"' in response.body
        elif response.status == 200 and kind == "image/png":
            assert response.body.startswith(b"\x89PNG") and "token=" + TOKEN in claims["path"] or f"X-SpaceDG-Token: {TOKEN}" in claims["headers"]
        elif claims["method"] != "HEAD" or response.body:
            assert kind == "application/json; charset=utf-8", f"{where}: {kind}"
            value = json.loads(response.body)
            assert isinstance(value, dict)
            if response.status >= 400:
                assert isinstance(value.get("error"), str) and value["error"], f"{where}: {value}"
        if response.status == 200 and claims["method"] == "POST":
            assert _authenticated_write(claims, port), f"{where}: an unauthenticated write was accepted"
            writes_ok += 1
    # the server still serves, the original is untouched, and every logged change came from a valid authenticated write
    entries = [json.loads(line) for line in served.store.log.read_text().splitlines()] if served.store.log.exists() else []
    assert len(entries) <= writes_ok
    assert all(e["reviewer"] == "fuzz-reviewer" for e in entries)
    assert served.store.table.read_bytes() == table
    if not entries:
        assert served.store.out.read_bytes() == original_out
    out_now = served.store.out.read_bytes()
    served.close()
    again = ReviewStore(served.store.table, lock=True)  # replaying the log rebuilds the same TSV
    assert again.out.read_bytes() == out_now
    again.close()
    summary = ", ".join(f"{status or 'closed'}: {count}" for status, count in sorted(statuses.items()))
    print(f"\nfuzz: {REQUESTS} requests, {writes_ok} accepted writes, {len(entries)} logged changes; statuses {summary}")
    assert statuses[200] > 20 and writes_ok > 0  # the fuzz reaches the real routes, not only the guards
