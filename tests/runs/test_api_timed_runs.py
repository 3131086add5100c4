"""Durable runs on a timed instance (docs/schedules.md#runs-in-time), on SQLite and PostgreSQL: the
built-in timed scenario by name, times on assignments, in the trace and the export, the chain in
decision order (verified online and offline), a replay with the same times, and bad timed input as a
422 naming the field and the task, with nothing stored."""

from __future__ import annotations

import json
from datetime import datetime
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.audit.test_docs_check_trace import check_trace_source
from tests.support.offline_check import check_offline
from tests.support.polling import wait_until

TIMED = {"scenario": "baseline_timed"}


def completed(client: TestClient, body: dict[str, Any]) -> dict[str, Any]:
    created = client.post("/runs", json=body)
    assert created.status_code == 202, created.text
    state = wait_until(client, created.json()["id"], timeout=120)
    assert state["status"] == "completed", state
    return state


def all_assignments(client: TestClient, run_id: str) -> list[dict[str, Any]]:
    return list(client.get(f"/runs/{run_id}", params={"limit": 1000}).json()["assignments"])


def test_a_timed_run_stores_times_and_its_chain_verifies(
    any_db_client: TestClient, tmp_path: Path
) -> None:
    client = any_db_client
    state = completed(client, TIMED)
    run_id = state["id"]
    assignments = all_assignments(client, run_id)
    assert len(assignments) == 36
    for a in assignments:
        assert a["end"] > a["start"] >= 0 and a["zone"] in {"A", "B", "C"}
        assert a["start_at"].startswith("2026-03-02T") and a["start_at"].endswith("+01:00")
    assert sorted(a["seq"] for a in assignments) == list(range(36))
    # Decided in time order, not queue order.
    assert [a["task_index"] for a in sorted(assignments, key=lambda a: a["seq"])] != list(range(36))
    trace = client.get(f"/runs/{run_id}/trace", params={"limit": 1000}).json()
    by_task = {a["task_index"]: a for a in assignments}
    for d in trace["decisions"]:
        a = by_task[d["task_index"]]
        assert (d["start"], d["end"], d["zone"], d["travel"]) == (
            a["start"],
            a["end"],
            a["zone"],
            a["travel"],
        )
        assert d["later_by"] >= 0
    verify = client.get(f"/runs/{run_id}/trace/verify").json()
    assert verify["ok"], verify

    export = tmp_path / "run.jsonl"
    export.write_text(client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text)
    decisions = [json.loads(x) for x in export.read_text().splitlines()]
    decisions = [x for x in decisions if x["type"] == "decision"]
    # In chain order: the order the graph decided.
    assert [x["seq"] for x in decisions] == list(range(36))
    assert all({"start", "end", "zone", "travel", "later_by"} <= x.keys() for x in decisions)
    script = tmp_path / "check_trace.py"
    script.write_text(check_trace_source())
    done = check_offline(export, script=script)
    assert done.returncode == 0, done.stderr
    # The times are in the chain: a moved end breaks it.
    lines = export.read_text().splitlines()
    at = next(i for i, x in enumerate(lines) if json.loads(x)["type"] == "decision")
    moved = json.loads(lines[at])
    moved["end"] += 1
    lines[at] = json.dumps(moved)
    export.write_text("\n".join(lines) + "\n")
    tampered = check_offline(export, script=script)
    assert tampered.returncode != 0 and "broken at decision" in tampered.stderr

    # A replay reproduces the times exactly, with no reasoner call.
    replay = completed(client, {"reasoner": "replay", "replay_of": run_id})
    again = all_assignments(client, replay["id"])
    keys = ("task_index", "robot", "start", "end", "zone", "travel", "seq")
    assert [[a[k] for k in keys] for a in again] == [[a[k] for k in keys] for a in assignments]


def test_an_untimed_run_has_no_time_fields(client: TestClient) -> None:
    state = completed(client, {"scenario": "baseline"})
    assignment = all_assignments(client, state["id"])[0]
    assert not {"start", "end", "zone", "travel", "seq"} & assignment.keys()
    decision = client.get(f"/runs/{state['id']}/trace").json()["decisions"][0]
    assert "start" not in decision


def timed_body(**changes: Any) -> dict[str, Any]:
    tasks: list[dict[str, Any]] = [
        {"id": "dig", "features": ["x"], "duration": 30, "zone": "A"},
        {"id": "pour", "features": ["x"], "duration": 20, "zone": "B", "after": ["dig"]},
    ]
    body: dict[str, Any] = {
        "tasks": tasks,
        "robots": [
            {"name": "r1", "success": {"x": 0.9}, "zone": "A"},
            {"name": "r2", "success": {"x": 0.6}, "zone": "B"},
        ],
        "travel": {"A": {"B": 5}},
    }
    for key, value in changes.items():
        if key.startswith("task1_"):
            tasks[1][key.removeprefix("task1_")] = value
        elif key.startswith("task0_"):
            tasks[0][key.removeprefix("task0_")] = value
        else:
            body[key] = value
    return body


BAD = [
    pytest.param(timed_body(task0_after=["pour"]), "tasks.0.after", "'pour' -> 'dig'", id="cycle"),
    pytest.param(timed_body(task1_after=["nowhere"]), "tasks.1.after", "pour", id="unknown-after"),
    pytest.param(timed_body(task1_duration=None), "tasks.1.duration", "pour", id="no-duration"),
    pytest.param(timed_body(task1_deadline=10), "tasks.1.deadline", "pour", id="deadline"),
    pytest.param(timed_body(travel={}), "travel", "A", id="no-travel"),
    pytest.param(
        {"scenario": "baseline", "objective": "makespan"}, "objective", "", id="objective"
    ),
    pytest.param({**TIMED, "start": "2026-03-02T08:00:00+01:00"}, "start", "", id="start"),
]


@pytest.mark.parametrize(("body", "field", "names"), BAD)
def test_bad_timed_input_is_a_422_naming_field_and_task_with_nothing_stored(
    any_db_client: TestClient, body: dict[str, Any], field: str, names: str
) -> None:
    client = any_db_client
    response = client.post("/runs", json=body)
    assert response.status_code == 422, response.text
    (error,) = response.json()["detail"]
    where = ".".join(str(part) for part in error["loc"][1:])
    assert where.startswith(field), error
    assert names in error["msg"], error
    assert client.get("/runs").json() == []


def test_a_timed_run_of_its_own_tasks_without_start_starts_at_its_arrival(
    client: TestClient,
) -> None:
    body = {
        "tasks": [
            {"id": "dig", "features": ["heavy"], "duration": 30},
            {"id": "pour", "features": ["careful"], "duration": 20, "after": ["dig"]},
        ],
        "robots": [
            {"name": "a", "success": {"heavy": 0.9, "careful": 0.4}},
            {"name": "b", "success": {"heavy": 0.5, "careful": 0.8}},
        ],
    }
    before = datetime.now().astimezone().replace(microsecond=0)
    run_id = completed(client, body)["id"]
    start = datetime.fromisoformat(client.get(f"/runs/{run_id}/schedule").json()["start"])
    assert before <= start <= datetime.now().astimezone()
