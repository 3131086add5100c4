"""The body limit over real HTTP (uvicorn): 413 for a declared and for a chunked body."""

from __future__ import annotations

import json
from collections.abc import Iterator
from pathlib import Path

import httpx
import pytest

from tests.support.server import Server

LIMIT = 2_000
TASKS = [{"id": i, "features": ["heavy"]} for i in range(200)]
ROBOTS = [{"name": "a", "success": {"heavy": 0.9}}, {"name": "b", "success": {"heavy": 0.3}}]


@pytest.mark.e2e
def test_over_long_bodies_are_413_over_real_http(tmp_path: Path) -> None:
    server = Server(tmp_path / "data", env={"LTAA_MAX_BODY_BYTES": str(LIMIT)}).start()
    body = json.dumps({"tasks": TASKS, "robots": ROBOTS}).encode()
    assert len(body) > LIMIT
    # No keys: the start-up warning names the address actually served (PORT of serve.sh).
    assert f"127.0.0.1:{server.port}" in server.log.read_text()

    def chunks() -> Iterator[bytes]:
        for start in range(0, len(body), 256):
            yield body[start : start + 256]

    try:
        with httpx.Client(base_url=server.url, timeout=30) as http:
            for path in ("/runs", "/allocate"):
                declared = http.post(
                    path, content=body, headers={"content-type": "application/json"}
                )
                streamed = http.post(
                    path, content=chunks(), headers={"content-type": "application/json"}
                )
                assert "content-length" not in streamed.request.headers
                assert streamed.request.headers["transfer-encoding"] == "chunked"
                for r in (declared, streamed):
                    assert r.status_code == 413, (path, r.text)
                    (item,) = r.json()["detail"]
                    assert item["loc"] == ["body"] and item["type"] == "body_too_large"
                    assert f"{LIMIT:,} bytes" in item["msg"]
            # The server is still serving, and no run was half-created.
            assert http.get("/runs").json() == []
            small = {"tasks": TASKS[:4], "robots": ROBOTS, "solver": "greedy"}
            assert http.post("/allocate", json=small).status_code == 200
    finally:
        server.stop()
