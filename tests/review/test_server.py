"""The review server's HTTP API (spacedg.review.server) over a real socket on 127.0.0.1."""

from __future__ import annotations

import json
import urllib.error
import urllib.request
from pathlib import Path

import cv2
import numpy as np
import pytest

from spacedg.cli import build_parser
from spacedg.review.server import serve_in_thread
from tests.eval_fixtures import write_bench


@pytest.fixture()
def server(tmp_path: Path):
    bench = write_bench(tmp_path / "bench")
    (bench / "images").mkdir()
    for index in range(15):
        cv2.imwrite(str(bench / "images" / f"{index:07d}_0.png"), np.full((24, 32, 3), index * 10, np.uint8))
    (tmp_path / "secret.txt").write_text("not served")
    running = serve_in_thread(bench, reviewer="tester", token=TOKEN)
    yield running
    running.close()


TOKEN = "test-token-0123456789"


def _get(url: str, token: str | None = TOKEN) -> tuple[int, bytes]:
    request = urllib.request.Request(url, headers={"X-SpaceDG-Token": token} if token else {})
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, response.read()
    except urllib.error.HTTPError as err:
        return err.code, err.read()


def _post(url: str, body: object, token: str | None = TOKEN) -> tuple[int, dict]:
    data = body if isinstance(body, bytes) else json.dumps(body).encode()
    headers = {"Content-Type": "application/json", **({"X-SpaceDG-Token": token} if token else {})}
    request = urllib.request.Request(url, data=data, headers=headers, method="POST")
    try:
        with urllib.request.urlopen(request, timeout=10) as response:
            return response.status, json.loads(response.read())
    except urllib.error.HTTPError as err:
        return err.code, json.loads(err.read())


def test_page_items_and_images(server) -> None:
    assert server.url == server.base_url + "?token=" + TOKEN
    status, page = _get(server.url, token=None)
    assert status == 200 and b'id="item-list"' in page
    status, body = _get(server.base_url + "api/items")
    listing = json.loads(body)
    assert status == 200 and len(listing["items"]) == 15 and listing["reviewer"] == "tester"
    status, body = _get(server.base_url + "api/items/5")
    item = json.loads(body)
    assert item["answer"] == "B" and item["degradation_type"] == "haze" and item["clean_index"] == 0
    status, png = _get(server.base_url + "images/" + item["image_paths"][0])
    assert status == 200 and png.startswith(b"\x89PNG")


def test_edit_round_trip_and_refusals(server) -> None:
    original = server.store.table.read_bytes()
    status, item = _post(server.base_url + "api/items/5/edit", {"changes": {"answer": "C"}})
    assert status == 200 and item["answer"] == "C" and item["edited"]
    log = server.store.log.read_text().splitlines()
    assert len(log) == 1 and json.loads(log[0])["after"] == {"answer": "C"}
    written = server.store.out.read_bytes()
    for body in ({"changes": {"answer": "E"}}, {"changes": {"colour": "red"}}, {"changes": "C"}, b"{not json"):
        status, reply = _post(server.base_url + "api/items/5/edit", body)
        assert status == 400 and reply["error"], body
    status, reply = _post(server.base_url + "api/items/8/edit", {"changes": {"answer": "2.5"}})  # a count
    assert status == 400 and "integer" in reply["error"]
    assert server.store.out.read_bytes() == written and len(server.store.log.read_text().splitlines()) == 1
    assert server.store.table.read_bytes() == original
    status, item = _post(server.base_url + "api/items/3/drop", {"dropped": True})
    assert status == 200 and item["dropped"]
    status, reply = _post(server.base_url + "api/items/3/drop", {"dropped": "yes"})
    assert status == 400


def test_bad_paths(server) -> None:
    assert _get(server.base_url + "images/../../secret.txt")[0] == 404
    assert _get(server.base_url + "images/%2e%2e/secret.txt")[0] == 404
    assert _get(server.base_url + "api/items/999")[0] == 400
    assert _get(server.base_url + "api/items/abc")[0] == 400
    assert _get(server.base_url + "nowhere")[0] == 404
    assert _post(server.base_url + "api/items/1/explode", {})[0] == 404


def test_cli_parser_knows_review() -> None:
    args = build_parser().parse_args(["review", "runs/bench", "--port", "0", "--reviewer", "me"])
    assert (args.port, args.reviewer) == (0, "me")
