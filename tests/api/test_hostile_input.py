"""Hostile input that reaches the database: on both back-ends, a 4xx naming the field, never
a 500 and never a run accepted only to fail.

PostgreSQL refuses a NUL character in any text value (SQLite stores it), so these run on both.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.support.polling import wait_until

RUN_PATHS = [
    ("GET", "/runs/{}"),
    ("GET", "/runs/{}/trace"),
    ("GET", "/runs/{}/trace/verify"),
    ("GET", "/runs/{}/trace?format=jsonl"),
    ("GET", "/runs/{}/events"),
    ("POST", "/runs/{}/resume"),
    ("POST", "/runs/{}/cancel"),
]


@pytest.mark.parametrize(("method", "path"), RUN_PATHS)
def test_a_nul_character_in_a_run_id_is_a_4xx_naming_the_path(
    any_db_client: TestClient, method: str, path: str
) -> None:
    response = any_db_client.request(method, path.format("a%00b"))
    assert 400 <= response.status_code < 500, response.text
    assert response.json()["detail"][0]["loc"] == ["path", "run_id"]


def _one_task(**task: Any) -> dict[str, Any]:
    robot = {"name": "crane", "success": {"heavy": 0.9}}
    return {
        "tasks": [{"id": 1, "name": "Lift", "features": ["heavy"], **task}],
        "robots": [robot],
        "reasoner": "rules",
    }


NUL_BODIES = {
    ("tasks", 0, "name"): _one_task(name="Li\x00ft"),
    ("tasks", 0, "id"): _one_task(id="t\x00"),
    ("tasks", 0, "type"): _one_task(type="Cu\x00stom"),
    ("robots", 0, "name"): {
        **_one_task(),
        "robots": [{"name": "cr\x00ane", "success": {"heavy": 0.9}}],
    },
    ("robots", 0, "label"): {
        **_one_task(),
        "robots": [{"name": "crane", "label": "C\x00", "success": {"heavy": 0.9}}],
    },
    ("model",): {**_one_task(), "model": "claude\x00"},
}


@pytest.mark.parametrize("loc", list(NUL_BODIES), ids=lambda loc: ".".join(map(str, loc)))
def test_a_nul_character_in_a_run_request_is_a_422_not_a_failed_run(
    any_db_client: TestClient, loc: tuple[str | int, ...]
) -> None:
    response = any_db_client.post("/runs", json=NUL_BODIES[loc])
    assert response.status_code == 422, response.text
    assert response.json()["detail"][0]["loc"][: len(loc) + 1] == ["body", *loc]
    assert "NUL" in response.json()["detail"][0]["msg"]
    assert any_db_client.get("/runs").json() == []  # nothing half-written


EVERY_DECISION = {**_one_task(), "review": {"on": ["every_decision"]}}


def _completed(client: TestClient) -> str:
    run_id = str(client.post("/runs", json=_one_task()).json()["id"])
    wait_until(client, run_id, ("completed",))
    return run_id


def _awaiting_review(client: TestClient) -> str:
    run_id = str(client.post("/runs", json=EVERY_DECISION).json()["id"])
    wait_until(client, run_id, ("awaiting_review",))
    return run_id


def _revision_reason(client: TestClient) -> tuple[Any, Callable[[], bool]]:
    run_id = _completed(client)
    answer = client.post(f"/runs/{run_id}/revisions", json={"reason": "fa\x00ult"})
    return answer, lambda: len(client.get(f"/runs/{run_id}/revisions").json()) == 1


def _override_reason(client: TestClient) -> tuple[Any, Callable[[], bool]]:
    run_id = _awaiting_review(client)
    body = {"action": "override", "robot": "crane", "reason": "booked\x00"}
    answer = client.post(f"/runs/{run_id}/reviews/0", json=body)
    return answer, lambda: [r["run_id"] for r in client.get("/reviews").json()] == [run_id]


def _approve_reason(client: TestClient) -> tuple[Any, Callable[[], bool]]:
    run_id = _awaiting_review(client)
    answer = client.post(f"/runs/{run_id}/reviews/0", json={"action": "approve", "reason": "\x00"})
    return answer, lambda: [r["run_id"] for r in client.get("/reviews").json()] == [run_id]


def _signoff_statement(client: TestClient) -> tuple[Any, Callable[[], bool]]:
    run_id = _completed(client)
    answer = client.post(f"/runs/{run_id}/signoff", json={"statement": "checked\x00"})
    return answer, lambda: client.get(f"/runs/{run_id}").json()["signoffs"] == []


def _webhook_description(client: TestClient) -> tuple[Any, Callable[[], bool]]:
    body = {"url": "https://site.example.com/hooks", "events": ["*"], "description": "b\x00"}
    answer = client.post("/webhooks", json=body)
    return answer, lambda: client.get("/webhooks").json() == []


def _review_task_id(client: TestClient) -> tuple[Any, Callable[[], bool]]:
    answer = client.post("/runs", json={**_one_task(), "review": {"task_ids": ["t\x00"]}})
    return answer, lambda: client.get("/runs").json() == []


FREE_TEXT = [
    (["body", "reason"], _revision_reason),
    (["body", "reason"], _override_reason),
    (["body", "reason"], _approve_reason),
    (["body", "statement"], _signoff_statement),
    (["body", "description"], _webhook_description),
    (["body", "review", "task_ids", 0], _review_task_id),
]


@pytest.mark.parametrize(
    ("loc", "case"), FREE_TEXT, ids=[case.__name__.lstrip("_") for _, case in FREE_TEXT]
)
def test_a_nul_character_in_free_text_is_a_422_naming_it_and_nothing_is_written(
    any_db_client: TestClient,
    loc: list[str | int],
    case: Callable[[TestClient], tuple[Any, Callable[[], bool]]],
) -> None:
    answer, untouched = case(any_db_client)
    assert answer.status_code == 422, answer.text
    detail = answer.json()["detail"]
    assert [(d["loc"], d["type"]) for d in detail] == [(loc, "nul_character")]
    assert "NUL" in detail[0]["msg"]
    assert untouched()
