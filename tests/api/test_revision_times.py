"""Time in living plans through the API (SPEC 16): `now` and `delay` on revisions, bad
input refused with nothing stored."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.api.test_revisions import completed_run, wait_status

UNTIMED = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}


def nothing_stored(client: TestClient, parent: str, runs_before: int) -> None:
    state = client.get(f"/runs/{parent}").json()
    assert state["superseded_by"] is None and state["status"] == "completed"
    assert [r["id"] for r in client.get(f"/runs/{parent}/revisions").json()] == [parent]
    assert len(client.get("/runs").json()) == runs_before


@pytest.mark.parametrize(
    ("body", "loc", "words"),
    [
        (
            {"changes": [{"type": "delay", "task_id": 3, "minutes": 10}]},
            ["body", "changes", 0],
            "not timed",
        ),
        (
            {"changes": [{"type": "delay", "task_id": 3, "minutes": 0}]},
            ["body", "changes", 0, "delay", "minutes"],
            "greater than 0",
        ),
        (
            {"changes": [{"type": "delay", "task_id": 3, "minutes": -5}]},
            ["body", "changes", 0, "delay", "minutes"],
            "greater than 0",
        ),
        ({"now": "2026-12-01T09:30:00"}, ["body", "now"], "offset"),
        ({"now": "tomorrow"}, ["body", "now"], "RFC 3339"),
        ({"now": 1764581400}, ["body", "now"], "RFC 3339"),
    ],
)
def test_bad_time_input_on_an_untimed_run_is_a_422_naming_the_field(
    client: TestClient, body: dict[str, Any], loc: list[Any], words: str
) -> None:
    parent = completed_run(client, UNTIMED)
    runs_before = len(client.get("/runs").json())
    response = client.post(f"/runs/{parent}/revisions", json={"reason": "test", **body})
    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert [d["loc"] for d in detail] == [loc], detail
    assert words in detail[0]["msg"], detail
    nothing_stored(client, parent, runs_before)


def test_now_on_an_untimed_run_changes_nothing(client: TestClient) -> None:
    parent = completed_run(client, UNTIMED)
    body = {"reason": "heavy down", "changes": [{"type": "robot_unavailable", "robot": "heavy"}]}
    plain = client.post(f"/runs/{parent}/revisions", json={**body, "pin": "decided"})
    assert plain.status_code == 202, plain.text
    other = completed_run(client, UNTIMED)
    timed = client.post(
        f"/runs/{other}/revisions",
        json={**body, "pin": "decided", "now": "2026-12-01T09:30:00Z"},
    )
    assert timed.status_code == 202, timed.text
    a = wait_status(client, plain.json()["id"], "completed")
    b = wait_status(client, timed.json()["id"], "completed")
    assert [(x["task_id"], x["robot"]) for x in a["assignments"]] == [
        (x["task_id"], x["robot"]) for x in b["assignments"]
    ]
    diff = client.get(f"/runs/{timed.json()['id']}/diff").json()
    assert diff["schedule"] is None
