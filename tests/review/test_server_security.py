"""The review server under hostile requests: token, Host and Origin allow-lists, JSON-only POSTs,
the reviewer fixed at start, only referenced images, security headers, timeouts and limits,
JSON errors, bounded connections, a locked output, refused truncated benches and bad ports."""

from __future__ import annotations

import errno
import json
import os
import socket
import subprocess
import sys
import threading
import time
from pathlib import Path

import cv2
import numpy as np
import pytest

from spacedg.errors import FileFormatError, ParameterError
from spacedg.review import server as server_module
from spacedg.review.server import MAX_CONNECTIONS, make_server, serve_in_thread
from tests.conftest import REPO_ROOT, ctrl_c_reaches_child
from tests.eval_fixtures import write_bench
from tests.review.http_raw import SECURITY_HEADERS, Response, request, send

TOKEN = "tok-" + "x" * 40
SPACEDG_SCRIPT = Path(sys.executable).parent / "spacedg"


@pytest.fixture()
def bench(tmp_path: Path) -> Path:
    folder = write_bench(tmp_path / "home" / "bench")
    (folder / "images").mkdir()
    for index in range(15):
        cv2.imwrite(str(folder / "images" / f"{index:07d}_0.png"), np.full((8, 8, 3), index, np.uint8))
    (folder / ".ssh").mkdir()
    (folder / ".ssh" / "id_rsa").write_text("PRIVATE KEY")
    (folder / "notes.png").write_bytes(b"\x89PNG not referenced by any row")
    (tmp_path / "home" / "secret.png").write_bytes(b"\x89PNG outside the bench")
    return folder


@pytest.fixture()
def server(bench: Path):
    running = serve_in_thread(bench, reviewer="ana", token=TOKEN)
    yield running
    running.close()


def _port(server) -> int:  # noqa: ANN001
    return int(server.httpd.server_address[1])


def _auth(**extra: str) -> dict[str, str]:
    return {"X-SpaceDG-Token": TOKEN, **extra}


def _edit(server, body: dict | bytes, **kwargs) -> Response:  # noqa: ANN001, ANN003
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    headers = kwargs.pop("headers", None)
    if headers is None:
        headers = _auth(**{"Content-Type": "application/json"})
    return request(_port(server), "POST", kwargs.pop("path", "/api/items/0/edit"), headers=headers, body=data, **kwargs)


def _files(server) -> tuple[bytes, bytes | None]:  # noqa: ANN001
    log = server.store.log
    return server.store.out.read_bytes(), log.read_bytes() if log.exists() else None


def _assert_json_error(response: Response, status: int) -> str:
    assert response.status == status, (response.status, response.raw[:300])
    assert response.header("content-type") == "application/json; charset=utf-8"
    assert SECURITY_HEADERS <= set(response.headers), sorted(response.headers)
    message = response.json()["error"]
    assert isinstance(message, str) and message and "Traceback" not in message
    return message


# ------------------------------------------------------------------ who may write
def test_the_reported_attack_is_refused(server) -> None:
    """The finding: a text/plain POST from another origin with a reviewer in the body."""
    before = _files(server)
    response = _edit(server, {"changes": {"answer": "42.0"}, "reviewer": "mallory"},
                     headers={"Content-Type": "text/plain", "Origin": "http://evil.example"})
    _assert_json_error(response, 403)
    assert _files(server) == before


@pytest.mark.parametrize(("headers", "status", "needle"), [
    ({"Content-Type": "application/json"}, 403, "no session token"),
    ({"Content-Type": "application/json", "X-SpaceDG-Token": "guess"}, 403, "wrong session token"),
    (_auth(**{"Content-Type": "text/plain"}), 415, "application/json"),
    (_auth(**{"Content-Type": "application/x-www-form-urlencoded"}), 415, "application/json"),
    (_auth(**{"Content-Type": "multipart/form-data; boundary=x"}), 415, "application/json"),
    (_auth(**{"Content-Type": "application/json; charset=latin-1"}), 415, "UTF-8"),
    (_auth(**{"Content-Type": "application/json", "Origin": "http://127.0.0.1:1"}), 403, "origin"),
    (_auth(**{"Content-Type": "application/json", "Origin": "null"}), 403, "origin"),
    (_auth(**{"Content-Type": "application/json", "Sec-Fetch-Site": "same-site"}), 403, "same-site"),
    (_auth(**{"Content-Type": "application/json", "Sec-Fetch-Site": "cross-site"}), 403, "cross-site"),
])
def test_writes_need_token_json_and_own_origin(server, headers: dict[str, str], status: int, needle: str) -> None:
    before = _files(server)
    message = _assert_json_error(_edit(server, {"changes": {"answer": "C"}}, headers=headers), status)
    assert needle in message
    assert _files(server) == before and not server.store.item(0)["edited"]


def test_token_in_the_query_does_not_authorise_a_post(server) -> None:
    before = _files(server)
    response = _edit(server, {"changes": {"answer": "C"}}, headers={"Content-Type": "application/json"},
                     path=f"/api/items/0/edit?token={TOKEN}")
    _assert_json_error(response, 403)
    assert _files(server) == before


def test_reviewer_comes_from_the_command_line(server) -> None:
    message = _assert_json_error(_edit(server, {"changes": {"answer": "C"}, "reviewer": "mallory"}), 400)
    assert "--reviewer" in message
    _assert_json_error(_edit(server, {"changes": {"answer": "C"}, "extra": 1}), 400)
    ok = _edit(server, {"changes": {"answer": "C"}}, headers=_auth(**{"Content-Type": "application/json",
                                                                       "Origin": f"http://127.0.0.1:{_port(server)}"}))
    assert ok.status == 200 and ok.json()["answer"] == "C"
    (entry,) = [json.loads(line) for line in server.store.log.read_text().splitlines()]
    assert entry["reviewer"] == "ana"


def test_same_origin_variants_are_served(server) -> None:
    port = _port(server)
    for host, origin in ((f"127.0.0.1:{port}", f"http://127.0.0.1:{port}"), (f"localhost:{port}", f"http://localhost:{port}")):
        response = request(port, "GET", "/api/items", headers=_auth(Origin=origin, **{"Sec-Fetch-Site": "same-origin"}), host=host)
        assert response.status == 200 and len(response.json()["items"]) == 15


# ------------------------------------------------------------------ who may read
@pytest.mark.parametrize("host", ["attacker.example", "attacker.example:PORT", "127.0.0.1:1", "127.0.0.1", ""])
def test_foreign_host_is_refused_even_with_the_token(server, host: str) -> None:
    port = _port(server)
    host = host.replace("PORT", str(port))
    for path in ("/api/items", "/", f"/images/images/0000000_0.png?token={TOKEN}"):
        response = request(port, "GET", path, headers=_auth(), host=host)
        message = _assert_json_error(response, 403)
        assert "is not this server" in message
        assert b"Where did the camera move" not in response.body


def test_missing_and_duplicate_host(server) -> None:
    port = _port(server)
    _assert_json_error(send(port, f"GET /api/items HTTP/1.0\r\nX-SpaceDG-Token: {TOKEN}\r\n\r\n".encode()), 403)
    twice = f"GET /api/items HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nHost: evil.example\r\nX-SpaceDG-Token: {TOKEN}\r\n\r\n"
    _assert_json_error(send(port, twice.encode()), 400)


def test_reads_need_the_token(server) -> None:
    port = _port(server)
    _assert_json_error(request(port, "GET", "/api/items"), 403)
    _assert_json_error(request(port, "GET", "/api/items/0"), 403)
    _assert_json_error(request(port, "GET", "/images/images/0000000_0.png"), 403)
    assert request(port, "GET", f"/images/images/0000000_0.png?token={TOKEN}").body.startswith(b"\x89PNG")
    assert request(port, "GET", "/api/items/0", headers=_auth()).json()["index"] == 0
    page = request(port, "GET", "/")  # the page itself is static and carries no data
    assert page.status == 200 and b'id="item-list"' in page.body and b"Where did the camera" not in page.body


def test_only_referenced_images_are_served(server) -> None:
    port = _port(server)
    for path in (".ssh/id_rsa", "notes.png", "../secret.png", "images/../notes.png", "%2e%2e/secret.png", "bench.tsv",
                 "images/0000099_0.png", "/etc/passwd"):
        response = request(port, "GET", f"/images/{path}?token={TOKEN}")
        _assert_json_error(response, 404)
        assert b"PRIVATE" not in response.body
    image = request(port, "GET", f"/images/images/0000003_0.png?token={TOKEN}")
    assert image.status == 200 and image.header("content-type") == "image/png"
    assert SECURITY_HEADERS <= set(image.headers) and image.header("x-content-type-options") == "nosniff"


def test_security_headers_on_every_kind_of_response(server) -> None:
    port = _port(server)
    for response in (request(port, "GET", "/"), request(port, "GET", "/api/items", headers=_auth()),
                     request(port, "GET", "/nowhere", headers=_auth()), request(port, "DELETE", "/api/items/0", headers=_auth()),
                     send(port, b"NONSENSE\r\n\r\n")):
        assert SECURITY_HEADERS <= set(response.headers), (response.status, sorted(response.headers))
        csp = response.header("content-security-policy")
        assert "frame-ancestors 'none'" in csp and "default-src 'none'" in csp and "'unsafe-inline'" not in csp
        assert response.header("x-frame-options") == "DENY" and response.header("referrer-policy") == "no-referrer"
        assert "access-control-allow-origin" not in response.headers


# ------------------------------------------------------------------ malformed and slow
def test_bad_lengths_and_bodies_get_json_errors_quickly(server) -> None:
    before = _files(server)
    cases = [
        ({"Content-Length": "-1"}, b"", 400),
        ({"Content-Length": "+5"}, b"{}", 400),
        ({"Content-Length": "1_0"}, b"{}", 400),
        ({"Content-Length": str(10**9)}, b"{}", 413),
        ({"Transfer-Encoding": "chunked"}, b"2\r\n{}\r\n0\r\n\r\n", 501),
        ({}, b"[" * 300_000, 413),
        ({}, b"[" * 100_000 + b"]" * 100_000, 400),
        ({}, b'{"changes": {"answer": NaN}}', 400),
        ({}, b"\xff\xfe{}", 400),
        ({}, b'"just a string"', 400),
        ({}, b'{"changes": {"answer": 3}}', 400),
        ({"Content-Length": "50"}, b'{"changes"', 400),  # a short body, then EOF
    ]
    for extra, body, status in cases:
        response = _edit(server, body, headers=_auth(**{"Content-Type": "application/json", **extra}))
        _assert_json_error(response, status)
        assert response.seconds < 5, (extra, response.seconds)
    no_length = f"POST /api/items/0/edit HTTP/1.1\r\nHost: 127.0.0.1:{_port(server)}\r\nX-SpaceDG-Token: {TOKEN}\r\n" \
                "Content-Type: application/json\r\n\r\n"
    _assert_json_error(send(_port(server), no_length.encode()), 411)
    assert _files(server) == before


def test_a_stalled_body_times_out_with_408(server, monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(server_module._Handler, "timeout", 0.5)
    before = _files(server)
    response = _edit(server, b'{"chan', headers=_auth(**{"Content-Type": "application/json", "Content-Length": "40"}), half_close=False)
    assert _assert_json_error(response, 408)
    assert response.seconds < 5
    assert _files(server) == before


def test_long_and_odd_paths(server) -> None:
    port = _port(server)
    _assert_json_error(request(port, "GET", "/images/" + "a/" * 3000, headers=_auth()), 414)
    _assert_json_error(request(port, "GET", "/images/" + "a/" * 900, headers=_auth()), 404)
    _assert_json_error(request(port, "GET", "/x" * 40_000, headers=_auth()), 414)  # over http.server's own line limit
    _assert_json_error(request(port, "GET", "/api/items/%ff", headers=_auth()), 400)
    _assert_json_error(request(port, "GET", "/api/items/1%000", headers=_auth()), 400)
    _assert_json_error(request(port, "GET", "/api/items/99999999999999999999", headers=_auth()), 400)
    _assert_json_error(request(port, "GET", "http://evil.example/api/items", headers=_auth()), 400)
    _assert_json_error(send(port, b"GET /\r\n\r\n"), 400)  # HTTP/0.9 gets a real status line too
    _assert_json_error(request(port, "OPTIONS", "/api/items/0/edit", headers=_auth()), 405)
    too_many = "".join(f"X-{i}: {i}\r\n" for i in range(120))
    _assert_json_error(send(port, f"GET / HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\n{too_many}\r\n".encode()), 431)


def test_disk_full_is_a_json_error_and_changes_nothing(server, monkeypatch: pytest.MonkeyPatch) -> None:
    from spacedg.review import store as store_module

    before = _files(server)

    def full(*args, **kwargs):  # noqa: ANN002, ANN003, ANN202
        raise OSError(errno.ENOSPC, "No space left on device", str(server.store.out))

    monkeypatch.setattr(store_module, "write_temp_sibling", full)
    message = _assert_json_error(_edit(server, {"changes": {"answer": "C"}}), 507)
    assert "No space left on device" in message and "nothing was changed" in message
    assert _files(server) == before and server.store.item(0)["answer"] == "B"
    monkeypatch.undo()
    assert _edit(server, {"changes": {"answer": "C"}}).status == 200


def test_connections_are_bounded(server, monkeypatch: pytest.MonkeyPatch) -> None:
    """The finding: 1,000 connections with a stalled body stopped the server at ~480 threads.
    Now at most MAX_CONNECTIONS are served at once (the rest get 503 at once), each for at most
    REQUEST_DEADLINE seconds, and the server answers again afterwards."""
    monkeypatch.setattr(server_module, "REQUEST_DEADLINE", 1.0)
    port = _port(server)
    threads_before = threading.active_count()
    stalled = []
    head = (f"POST /api/items/0/edit HTTP/1.1\r\nHost: 127.0.0.1:{port}\r\nX-SpaceDG-Token: {TOKEN}\r\n"
            "Content-Type: application/json\r\nContent-Length: 100\r\n\r\n{").encode()
    try:
        for _ in range(200):
            sock = socket.create_connection(("127.0.0.1", port), timeout=5)
            sock.sendall(head)
            stalled.append(sock)
        time.sleep(0.3)
        assert threading.active_count() <= threads_before + MAX_CONNECTIONS + 2
        busy = request(port, "GET", "/api/items", headers=_auth(), timeout=5)
        assert busy.status in (503, 200) and busy.seconds < 3
        if busy.status == 503:
            _assert_json_error(busy, 503)
        deadline = time.monotonic() + 15
        while time.monotonic() < deadline:  # the stalled ones are cut after REQUEST_DEADLINE
            ok = request(port, "GET", "/api/items", headers=_auth(), timeout=5)
            if ok.status == 200:
                break
            time.sleep(0.2)
        assert ok.status == 200
    finally:
        for sock in stalled:
            sock.close()
    assert server.store.log.exists() is False


# ------------------------------------------------------------------ starting
def test_second_review_of_one_output_is_refused(server, bench: Path) -> None:
    with pytest.raises(ParameterError, match=r"being reviewed by another spacedg review \(pid \d+"):
        make_server(bench, port=0)
    other = make_server(bench, out=bench / "mine.tsv", port=0)  # another output is fine
    other.close()


def test_lock_is_freed_on_close(bench: Path) -> None:
    first = serve_in_thread(bench, token=TOKEN)
    first.close()
    again = serve_in_thread(bench, token=TOKEN)
    again.close()
    assert not (bench / "bench.reviewed.tsv.lock").exists()


@pytest.mark.parametrize("cut", ["-1", "-7", "-40", "last row's third field"])
def test_truncated_bench_is_refused(bench: Path, cut: str) -> None:
    """A cut anywhere but exactly at a row's end is refused (over every byte of this bench: 4,020
    of 4,034 cuts, where load_bench refuses 1,322, all of them among those)."""
    from spacedg.eval.bench import load_bench

    table = bench / "bench.tsv"
    data = table.read_bytes()
    last_row = data.rfind(b"\n", 0, len(data) - 1) + 1
    end = data.index(b"\t", data.index(b"\t", last_row) + 1) + 1 if not cut.startswith("-") else len(data) + int(cut)
    table.write_bytes(data[:end])
    with pytest.raises(FileFormatError, match="bench.tsv"):
        make_server(bench, port=0)
    assert not (bench / "bench.reviewed.tsv").exists()
    if not cut.startswith("-"):
        with pytest.raises(FileFormatError):
            load_bench(bench)  # the check load_bench does refuses it too
        table.write_bytes(data[:end] + b"\n")  # even with a line break added
        with pytest.raises(FileFormatError, match="looks truncated"):
            make_server(bench, port=0)


def test_a_killed_writers_temp_file_is_removed_on_start(bench: Path) -> None:
    stale = bench / ".bench.reviewed.tsv.abc12_xy.tmp"
    stale.write_text("half a table")
    keep = bench / ".bench.tsv.abc12_xy.tmp"  # not ours: another file's name
    keep.write_text("x")
    running = serve_in_thread(bench, token=TOKEN)
    running.close()
    assert not stale.exists() and keep.exists()


def _cli(*args: str) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    return subprocess.run([str(SPACEDG_SCRIPT), *args], capture_output=True, text=True, timeout=60, env=env)


@pytest.mark.parametrize(("args", "needle"), [
    (["--port", "70000"], "--port must be a whole number from 0 to 65535"),
    (["--port", "-1"], "--port must be a whole number from 0 to 65535"),
    (["--reviewer", " "], "--reviewer must be a non-empty name"),
    (["--reviewer", "a\nb"], "--reviewer"),
])
def test_cli_bad_arguments_write_nothing(bench: Path, args: list[str], needle: str) -> None:
    result = _cli("review", str(bench), *args)
    assert result.returncode == 2
    assert result.stderr.strip().count("\n") == 0 and needle in result.stderr, result.stderr
    assert not (bench / "bench.reviewed.tsv").exists()


def test_cli_prints_the_tokened_url(bench: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    process = subprocess.Popen([str(SPACEDG_SCRIPT), "review", str(bench), "--port", "0", "--reviewer", "cy"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env,
                               preexec_fn=ctrl_c_reaches_child)
    try:
        lines = [process.stdout.readline() for _ in range(3)]
        url = lines[2].split()[1]
        assert url.startswith("http://127.0.0.1:") and "/?token=" in url
        port = int(url.split(":")[2].split("/")[0])
        token = url.split("token=")[1]
        assert len(token) >= 40
        assert request(port, "GET", "/api/items", headers={"X-SpaceDG-Token": token}).json()["reviewer"] == "cy"
        assert request(port, "GET", "/api/items").status == 403
    finally:
        process.send_signal(2)
        out, err = process.communicate(timeout=20)
    assert process.returncode == 0 and "Traceback" not in err, err
    assert not (bench / "bench.reviewed.tsv.lock").exists()


def test_cli_stops_cleanly_on_sigterm(bench: Path) -> None:
    env = {**os.environ, "PYTHONPATH": str(REPO_ROOT)}
    process = subprocess.Popen([str(SPACEDG_SCRIPT), "review", str(bench), "--port", "0", "--reviewer", "cy"],
                               stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True, env=env)
    try:
        lines = [process.stdout.readline() for _ in range(3)]
        assert lines[2].startswith("open http://127.0.0.1:") and (bench / "bench.reviewed.tsv.lock").exists()
    finally:
        process.send_signal(15)
        out, err = process.communicate(timeout=20)
    assert process.returncode == 0 and out.strip().endswith("stopped") and "Traceback" not in err, err
    assert not (bench / "bench.reviewed.tsv.lock").exists()


def test_a_stop_signal_landing_on_another_thread_still_wakes_the_server() -> None:
    """The review command waits on the signals' wakeup descriptor, not on the main thread's pending-signal
    flag: a SIGINT handled by another thread's C handler (here one sent to that thread) stops the wait."""
    import signal
    import threading

    from spacedg.commands.review import _stop_signals

    before = signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)
    with _stop_signals() as stopped:
        assert stopped is not None
        waiting = threading.Thread(target=stopped, daemon=True)
        waiting.start()
        sender = threading.Thread(target=lambda: signal.pthread_kill(threading.get_ident(), signal.SIGINT))
        sender.start()
        sender.join()
        waiting.join(timeout=10)
        assert not waiting.is_alive()  # the byte reached the descriptor
    assert (signal.getsignal(signal.SIGINT), signal.getsignal(signal.SIGTERM)) == before
