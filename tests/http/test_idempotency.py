"""Idempotency-Key on POST /runs: a retried request gets the run its first try created, a
reused key with another body is a 409, and concurrent retries never create two runs."""

from __future__ import annotations

import json
import threading
from collections.abc import Callable
from pathlib import Path
from typing import Any

import httpx
import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr

from app.store.db import make_engine, make_session_factory
from app.store.idempotency import request_digest
from app.store.models import Run
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until
from tests.support.server import Server

BODY: dict[str, Any] = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
KEY = "retry-3f1c9a7e-5b2d-4e8f-9a01-6c7d8e9f0a1b"


def post(client: TestClient, body: Any, key: str | None = KEY, **headers: str) -> Any:
    if key is not None:
        headers["Idempotency-Key"] = key
    return client.post("/runs", json=body, headers=headers)


def run_ids(client: TestClient, headers: dict[str, str] | None = None) -> list[str]:
    return [
        r["id"] for r in client.get("/runs", params={"limit": 500}, headers=headers or {}).json()
    ]


def stored_runs(data_dir: Path) -> list[Run]:
    engine = make_engine(f"sqlite:///{data_dir.as_posix()}/ltaa.db")
    try:
        with make_session_factory(engine)() as session:
            return list(session.query(Run))
    finally:
        engine.dispose()


def test_same_key_and_body_returns_the_first_run(client: TestClient) -> None:
    first = post(client, BODY)
    assert first.status_code == 202, first.text
    assert "idempotent-replayed" not in first.headers
    # The same body with its keys in another order and other whitespace: the same request.
    again = client.post(
        "/runs",
        content=json.dumps(dict(reversed(BODY.items())), indent=4),
        headers={"Idempotency-Key": KEY, "Content-Type": "application/json"},
    )
    assert again.status_code == 202, again.text
    assert again.json() == first.json()
    assert again.headers["location"] == first.headers["location"] == f"/runs/{first.json()['id']}"
    assert again.headers["idempotent-replayed"] == "true"
    assert run_ids(client) == [first.json()["id"]]


def test_a_replay_after_the_run_completed_answers_as_the_first_time(client: TestClient) -> None:
    first = post(client, BODY).json()
    wait_until(client, first["id"], ("completed",), timeout=60)
    again = post(client, BODY)
    assert again.status_code == 202
    assert again.json() == first and first["status"] == "queued"


def test_same_key_with_another_body_is_a_409_naming_the_header(client: TestClient) -> None:
    first = post(client, BODY).json()
    r = post(client, {**BODY, "mode": "success_focused"})
    assert r.status_code == 409, r.text
    (item,) = r.json()["detail"]
    assert item["loc"] == ["header", "Idempotency-Key"]
    assert item["type"] == "idempotency_key_reused"
    assert "different request body" in item["msg"] and first["id"] in item["msg"]
    assert "new key" in item["msg"]  # and how to fix it
    assert run_ids(client) == [first["id"]]


def test_omitted_and_explicit_null_cap_are_different_requests(client: TestClient) -> None:
    # Omitted max_deviation means the mode's cap, null means no cap: not the same run.
    assert post(client, BODY).status_code == 202
    assert post(client, {**BODY, "max_deviation": None}).status_code == 409


def test_task_aliases_are_the_same_request(client: TestClient) -> None:
    robots = [{"name": "a", "success": {"heavy": 0.9}}, {"name": "b", "success": {"heavy": 0.4}}]
    by_id = {"tasks": [{"id": 1, "features": ["heavy"]}], "robots": robots}
    by_teach_key = {"tasks": [{"action_id": 1, "features": ["heavy"]}], "robots": robots}
    first = post(client, by_id)
    again = post(client, by_teach_key)
    assert (first.status_code, again.status_code) == (202, 202)
    assert again.json()["id"] == first.json()["id"]


@pytest.mark.parametrize(
    ("key", "type_"), [("", "string_too_short"), ("k" * 256, "string_too_long")]
)
def test_an_empty_or_over_long_key_is_a_422_naming_the_header(
    client: TestClient, key: str, type_: str
) -> None:
    r = post(client, BODY, key=key)
    assert r.status_code == 422, r.text
    (item,) = r.json()["detail"]
    assert item["loc"] == ["header", "Idempotency-Key"] and item["type"] == type_
    assert run_ids(client) == []


def test_a_key_of_255_characters_is_accepted(client: TestClient) -> None:
    first = post(client, BODY, key="k" * 255)
    assert first.status_code == 202
    assert post(client, BODY, key="k" * 255).json()["id"] == first.json()["id"]


def test_without_a_key_every_request_starts_a_run(client: TestClient) -> None:
    ids = {post(client, BODY, key=None).json()["id"] for _ in range(2)}
    assert len(ids) == 2


def test_keys_are_global_not_per_api_key(make_client: ClientFactory) -> None:
    site_a, site_b = "site-a-client-key-0123456789", "site-b-client-key-0123456789"
    client = make_client(api_keys=SecretStr(f"{site_a}:client,{site_b}:client"))
    first = post(client, BODY, Authorization=f"Bearer {site_a}")
    again = post(client, BODY, Authorization=f"Bearer {site_b}")
    assert (first.status_code, again.status_code) == (202, 202)
    assert again.json()["id"] == first.json()["id"]


def test_the_stored_digest_is_the_canonical_body_digest(client: TestClient, settings: Any) -> None:
    run_id = post(client, BODY).json()["id"]
    (run,) = stored_runs(settings.data_dir)
    assert (run.id, run.idempotency_key) == (run_id, KEY)
    assert (
        run.request_digest == request_digest(BODY) == request_digest(dict(reversed(BODY.items())))
    )
    assert len(run.request_digest) == 64


def _at_once(n: int, call: Callable[[int], Any]) -> list[Any]:
    """Run call(i) on n threads released together by a barrier."""
    barrier = threading.Barrier(n)
    results: list[Any] = [None] * n

    def worker(i: int) -> None:
        barrier.wait()
        results[i] = call(i)

    threads = [threading.Thread(target=worker, args=(i,)) for i in range(n)]
    for t in threads:
        t.start()
    for t in threads:
        t.join(timeout=60)
    return results


def test_concurrent_retries_create_one_run(client: TestClient, settings: Any) -> None:
    for round_ in range(3):
        key = f"{KEY}-{round_}"

        def send(_i: int, key: str = key) -> Any:
            return post(client, BODY, key=key)

        responses = _at_once(8, send)
        assert {r.status_code for r in responses} == {202}, [r.text for r in responses]
        assert len({r.json()["id"] for r in responses}) == 1
        # One request created it; every other one was answered with that run.
        assert sum(r.headers.get("idempotent-replayed") == "true" for r in responses) == 7
    assert len(stored_runs(settings.data_dir)) == 3


def test_concurrent_requests_with_different_bodies_one_wins(client: TestClient) -> None:
    modes = ["balanced", "success_focused", "aggressive_balance"] * 2
    responses = _at_once(len(modes), lambda i: post(client, {**BODY, "mode": modes[i]}))
    created = [r for r in responses if r.status_code == 202]
    refused = [r for r in responses if r.status_code == 409]
    assert len(created) + len(refused) == len(modes), [r.text for r in responses]
    assert len({r.json()["id"] for r in created}) == 1  # the winner and its own-body retries
    assert len(created) == 2 and len(refused) == 4
    assert len(run_ids(client)) == 1


@pytest.mark.e2e
def test_concurrent_retries_against_a_real_server(tmp_path: Path) -> None:
    server = Server(tmp_path / "data", env={"LTAA_MAX_CONCURRENT_RUNS": "1"}).start()
    try:
        with httpx.Client(base_url=server.url, timeout=30) as http:
            responses = _at_once(
                10, lambda _i: http.post("/runs", json=BODY, headers={"Idempotency-Key": KEY})
            )
            assert {r.status_code for r in responses} == {202}, [r.text for r in responses]
            assert len({r.json()["id"] for r in responses}) == 1
            assert [r["id"] for r in http.get("/runs").json()] == [responses[0].json()["id"]]
    finally:
        server.stop()


@pytest.mark.parametrize("keys", [("key-a", "key-b"), ("key-a", "key-a")])
def test_two_idempotency_key_headers_are_a_422_naming_the_header(
    client: TestClient, keys: tuple[str, str]
) -> None:
    # Which key would a retry have to repeat? Picking one silently (or a proxy joining them
    # into "key-a, key-b") would make retries start runs; one key per request.
    r = client.post("/runs", json=BODY, headers=[("Idempotency-Key", k) for k in keys])
    assert r.status_code == 422, r.text
    assert r.json()["detail"][0]["loc"] == ["header", "Idempotency-Key"]
    assert run_ids(client) == []
