"""One answer shape in time (docs/schedules.md, "In `/allocate`"): on a timed instance an
`/allocate` assignment carries the time fields a timed run's assignment carries, copied from
its `schedule.tasks` row; an untimed answer's assignments carry none."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from app.runs.time_schemas import DecisionTimes
from tests.allocation.test_api_timed import ROBOTS, TASKS, TRAVEL, timed
from tests.runs.test_api_timed_runs import all_assignments, completed

TIME_FIELDS = {"start", "end", "start_at", "end_at", "zone", "travel"}


def test_the_time_fields_are_a_runs_own_less_what_only_a_run_decides() -> None:
    # seq and later_by describe the order a run's graph decided in: /allocate has none.
    assert set(DecisionTimes.model_fields) - {"seq", "later_by"} == TIME_FIELDS


def test_allocate_assignments_carry_the_times_of_their_schedule_rows(client: TestClient) -> None:
    for solver in ("schedule", "greedy"):
        answer = client.post("/allocate", json=timed(solver)).json()
        rows = {row["task_id"]: row for row in answer["schedule"]["tasks"]}
        for a in answer["assignments"]:
            row = rows[a["task_id"]]
            assert set(a) >= TIME_FIELDS, a
            assert {key: a[key] for key in TIME_FIELDS} == {key: row[key] for key in TIME_FIELDS}
            assert a["robot"] == row["robot"]


def test_allocate_following_a_runs_plan_answers_the_runs_times(client: TestClient) -> None:
    body: dict[str, Any] = {"tasks": TASKS, "robots": ROBOTS, "travel": TRAVEL}
    run = completed(client, {**body, "start": timed()["start"], "reasoner": "rules"})
    planned = all_assignments(client, run["id"])
    # The same robots and starts, pinned: the list scheduler times them as the run did.
    pins = [{"task_id": a["task_id"], "robot": a["robot"], "start": a["start"]} for a in planned]
    answer = client.post("/allocate", json=timed("greedy", pinned=pins)).json()
    assert answer["schedule_violations"] == []
    for ours, theirs in zip(answer["assignments"], planned, strict=True):
        assert {k: ours[k] for k in TIME_FIELDS} == {k: theirs[k] for k in TIME_FIELDS}


def test_an_untimed_answers_assignments_carry_no_time_fields(client: TestClient) -> None:
    answer = client.post("/allocate", json={"solver": "greedy", "scenario": "baseline"}).json()
    assert all(not TIME_FIELDS & set(a) for a in answer["assignments"])


def test_the_openapi_document_describes_the_time_fields(client: TestClient) -> None:
    schemas = client.get("/openapi.json").json()["components"]["schemas"]
    properties = schemas["Assignment"]["properties"]
    assert set(properties) >= TIME_FIELDS
    for key in TIME_FIELDS:
        assert properties[key]["description"].startswith("Timed instances"), key
    assert "start" not in schemas["Assignment"].get("required", [])
