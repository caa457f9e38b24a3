"""``spacedg review`` against other origins, in a real headless Chromium.

A hostile page served from another port of 127.0.0.1 tries to write (``fetch`` with and
without CORS mode, with and without a leaked token, and plain HTML forms submitted by a click,
no script needed) and to read (``fetch`` of ``/api/items`` in both modes, an image drawn into a
canvas). A DNS-rebinding page (``rebind.test`` resolved to 127.0.0.1 by the browser, so the
review server is "same origin" to it) tries the same with the real token. Nothing is written
and nothing is read; the review page itself still works in the same browser.
"""

from __future__ import annotations

import json
import threading
from http.server import BaseHTTPRequestHandler, ThreadingHTTPServer
from pathlib import Path

import pytest

from tests.eval_fixtures import write_bench
from tests.review.test_browser import _write_views, launch_chromium

REBIND_HOST = "rebind.test"


@pytest.fixture(scope="module")
def hostile_browser():
    with launch_chromium(f"--host-resolver-rules=MAP {REBIND_HOST} 127.0.0.1") as chromium:
        yield chromium


class _Evil(BaseHTTPRequestHandler):
    page = b""

    def do_GET(self) -> None:  # noqa: N802
        self.send_response(200)
        self.send_header("Content-Type", "text/html; charset=utf-8")
        self.send_header("Content-Length", str(len(self.page)))
        self.end_headers()
        self.wfile.write(self.page)

    def log_message(self, format: str, *args: object) -> None:  # noqa: A002
        pass


def _evil_page(base: str, token: str) -> bytes:
    """Plain HTML forms (text/plain crafted to look like JSON, urlencoded, with a leaked token in
    the action) aimed at the review server, each with its own sink frame and submit button."""
    forms = [
        ("f1", f"{base}api/items/1/drop", "text/plain", '{"dropped":true,"x":"', '"}'),
        ("f2", f"{base}api/items/2/edit?token={token}", "text/plain", '{"changes":{"answer":"4.5"},"x":"', '"}'),
        ("f3", f"{base}api/items/3/edit?token={token}", "application/x-www-form-urlencoded", "changes", '{"answer":"9"}'),
    ]
    html = ["<!doctype html><html><body><h1>a page on another port</h1>"]
    for name, action, enctype, field, value in forms:
        html.append(f"<form method=POST action='{action}' enctype='{enctype}' target='sink-{name}'>"
                    f"<input type=hidden name='{field}' value='{value}'><button id='{name}' type=submit>go</button></form>"
                    f"<iframe name='sink-{name}'></iframe>")
    html.append("</body></html>")
    return "".join(html).encode()


ATTACKS = """async ([base, token]) => {
  const out = {};
  const attempt = async (name, fn) => { try { out[name] = await fn(); } catch (e) { out[name] = "blocked: " + e.name; } };
  const json = JSON.stringify({changes: {answer: "C"}});
  await attempt("cors_json_edit", async () => {
    const r = await fetch(base + "api/items/0/edit", {method: "POST", headers: {"Content-Type": "application/json"}, body: json});
    return "read " + r.status + " " + await r.text(); });
  await attempt("cors_json_edit_leaked_token", async () => {
    const r = await fetch(base + "api/items/0/edit", {method: "POST", body: json,
      headers: {"Content-Type": "application/json", "X-SpaceDG-Token": token}});
    return "read " + r.status + " " + await r.text(); });
  await attempt("no_cors_text_edit", async () => {
    const r = await fetch(base + "api/items/0/edit", {method: "POST", mode: "no-cors", headers: {"Content-Type": "text/plain"}, body: json});
    return "opaque " + r.type + " " + r.status; });
  await attempt("no_cors_text_edit_leaked_token", async () => {
    const r = await fetch(base + "api/items/4/drop?token=" + token, {method: "POST", mode: "no-cors",
      headers: {"Content-Type": "text/plain"}, body: JSON.stringify({dropped: true})});
    return "opaque " + r.type + " " + r.status; });
  await attempt("cors_get_items", async () => { const r = await fetch(base + "api/items"); return "read " + r.status + " " + await r.text(); });
  await attempt("cors_get_items_leaked_token", async () => {
    const r = await fetch(base + "api/items?token=" + token); return "read " + r.status + " " + await r.text(); });
  await attempt("no_cors_get_items_leaked_token", async () => {
    const r = await fetch(base + "api/items?token=" + token, {mode: "no-cors"}); const t = await r.text();
    return "opaque " + r.type + " length " + t.length; });
  await attempt("image_pixels_leaked_token", () => new Promise((resolve) => {
    const img = new Image();
    img.onload = () => { const c = document.createElement("canvas"); c.width = 4; c.height = 4; const g = c.getContext("2d");
      g.drawImage(img, 0, 0); try { resolve("read " + g.getImageData(0, 0, 1, 1).data.join(",")); } catch (e) { resolve("blocked: " + e.name); } };
    img.onerror = () => resolve("blocked: load error");
    img.src = base + "images/images/0000000_0.png?token=" + token; }));
  return out;
}"""

REBIND = """async ([token]) => {
  const out = {};
  const r1 = await fetch("/api/items?token=" + token);
  out.get_items = r1.status + " " + await r1.text();
  const r2 = await fetch("/api/items/0", {headers: {"X-SpaceDG-Token": token}});
  out.get_item = r2.status + " " + await r2.text();
  const r3 = await fetch("/api/items/0/edit", {method: "POST", body: JSON.stringify({changes: {answer: "C"}}),
    headers: {"Content-Type": "application/json", "X-SpaceDG-Token": token}});
  out.edit = r3.status + " " + await r3.text();
  return out;
}"""


def test_other_origins_can_neither_write_nor_read(hostile_browser, tmp_path: Path, monkeypatch: pytest.MonkeyPatch) -> None:
    from playwright.sync_api import expect

    from spacedg.review import server as server_module
    from spacedg.review.server import serve_in_thread

    seen: list[tuple[str, str, int, str | None]] = []  # what reached the server and what it answered
    send_response = server_module._Handler.send_response

    def recording(self, code, message=None):  # noqa: ANN001, ANN202
        seen.append((self.command, self.path, int(code), self.headers.get("Origin") if self.headers else None))
        return send_response(self, code, message)

    monkeypatch.setattr(server_module._Handler, "send_response", recording)

    bench = write_bench(tmp_path / "bench")
    _write_views(bench)
    server = serve_in_thread(bench, reviewer="tester", port=0)
    port = int(server.httpd.server_address[1])
    _Evil.page = _evil_page(server.base_url, server.token)
    evil = ThreadingHTTPServer(("127.0.0.1", 0), _Evil)
    threading.Thread(target=evil.serve_forever, daemon=True).start()
    context = hostile_browser.new_context()
    try:
        before = server.store.out.read_bytes()
        page = context.new_page()
        page.goto(f"http://127.0.0.1:{evil.server_address[1]}/")
        results = page.evaluate(ATTACKS, [server.base_url, server.token])
        for name, outcome in results.items():  # every cross-origin read is blocked by the browser or sees nothing
            assert outcome.startswith(("blocked:", "opaque")), (name, outcome)
            assert "Where did the camera" not in outcome and "items" not in outcome, (name, outcome)
        assert results["image_pixels_leaked_token"].startswith("blocked:")
        for form in ("f1", "f2", "f3"):  # plain HTML forms, submitted by a click (no script on the page)
            with page.expect_event("framenavigated", predicate=lambda f, n=form: f.name == f"sink-{n}"):
                page.click(f"#{form}")
        page.wait_for_timeout(300)

        rebind = context.new_page()
        response = rebind.goto(f"http://{REBIND_HOST}:{port}/")
        assert response.status == 403 and "not this server" in json.loads(response.text())["error"]
        stolen = rebind.evaluate(REBIND, [server.token])
        for name, outcome in stolen.items():
            assert outcome.startswith("403 ") and "not this server" in outcome and "Where did the camera" not in outcome, (name, outcome)

        # the server refused every request of the other origins itself (whatever the browser let through)
        posts = [(path, code) for method, path, code, origin in seen if method == "POST"]
        assert len(posts) >= 5 and all(code == 403 for _, code in posts), posts
        assert all(code == 403 for method, path, code, origin in seen if origin and str(port) not in origin), seen
        assert not server.store.log.exists(), server.store.log.read_text()
        assert server.store.out.read_bytes() == before
        assert not any(server.store.item(i)["dropped"] or server.store.item(i)["edited"] for i in range(15))

        own = context.new_page()  # the real page, same browser: works
        own.goto(server.url)
        expect(own.locator("#count")).to_have_text("15 of 15")
        assert "token=" not in own.url  # taken off the address bar, kept for the tab
        own.reload()
        expect(own.locator("#count")).to_have_text("15 of 15")
        own.click('#item-list li[data-index="7"]')
        expect(own.locator("#detail")).to_have_attribute("data-index", "7")
        own.click("#drop")
        expect(own.locator("#drop")).to_have_text("Restore")
        assert [json.loads(line)["reviewer"] for line in server.store.log.read_text().splitlines()] == ["tester"]
    finally:
        context.close()
        evil.shutdown()
        evil.server_close()
        server.close()


def test_page_without_its_token_says_how_to_open_it(hostile_browser, tmp_path: Path) -> None:
    from playwright.sync_api import expect

    from spacedg.review.server import serve_in_thread

    bench = write_bench(tmp_path / "bench")
    server = serve_in_thread(bench, reviewer="tester", port=0)
    context = hostile_browser.new_context()
    try:
        page = context.new_page()
        page.goto(server.base_url)
        expect(page.locator("#error")).to_contain_text("session token")
        expect(page.locator("#item-list li")).to_have_count(0)
    finally:
        context.close()
        server.close()
