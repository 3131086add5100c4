"""The revision rules of docs/living-plans.md#revisions through the API: queue building, rates,
fleet, the cap, contradictions; and a 30-case bad-input battery for the two new endpoints."""

from __future__ import annotations

import math
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.domain import catalog
from tests.plans.test_revisions import BASELINE, completed_run, revise, wait_status

PIN_17 = {"through_task_index": 17}
HEAVY_DOWN = {"type": "robot_unavailable", "robot": "heavy"}


def assignments(client: TestClient, run_id: str) -> list[dict[str, Any]]:
    return list(client.get(f"/runs/{run_id}").json()["assignments"])


def test_add_tasks_next_goes_right_after_the_pins(client: TestClient) -> None:
    parent = completed_run(client)
    urgent = [{"id": f"U{i}", "name": "Shore trench", "features": ["heavy"]} for i in range(2)]
    created = revise(
        client,
        parent,
        {
            "changes": [
                {"type": "add_tasks", "tasks": urgent, "position": "next"},
                {"type": "add_tasks", "tasks": [{"id": "L1", "features": ["careful"]}]},
            ],
            "pin": PIN_17,
            "reason": "urgent shoring",
        },
    )
    state = wait_status(client, created["id"], "completed")
    ids = [a["task_id"] for a in state["assignments"]]
    parent_ids = [a["task_id"] for a in assignments(client, parent)]
    assert ids == [*parent_ids[:18], "U0", "U1", *parent_ids[18:], "L1"]
    diff = client.get(f"/runs/{created['id']}/diff").json()
    assert diff["added_tasks"] == ["U0", "U1", "L1"] and diff["removed_tasks"] == []


def test_remove_tasks(client: TestClient) -> None:
    parent = completed_run(client)
    parent_ids = [a["task_id"] for a in assignments(client, parent)]
    pinned = client.post(
        f"/runs/{parent}/revisions",
        json={
            "changes": [{"type": "remove_tasks", "task_ids": [parent_ids[3]]}],
            "pin": PIN_17,
            "reason": "x",
        },
    )
    assert pinned.status_code == 422, pinned.text
    assert pinned.json()["detail"][0]["loc"] == ["body", "changes", 0, "task_ids", 0]
    assert "pinned" in pinned.text
    gone = parent_ids[30]
    created = revise(
        client,
        parent,
        {"changes": [{"type": "remove_tasks", "task_ids": [gone]}], "pin": PIN_17, "reason": "x"},
    )
    state = wait_status(client, created["id"], "completed")
    assert [a["task_id"] for a in state["assignments"]] == [t for t in parent_ids if t != gone]


def test_set_rates_changes_success_for_the_unpinned_tasks_only(client: TestClient) -> None:
    parent = completed_run(client)
    before = assignments(client, parent)
    created = revise(
        client,
        parent,
        {
            "changes": [{"type": "set_rates", "robot": "light", "success": {"heavy": 0.95}}],
            "pin": PIN_17,
            "reason": "light robot re-rated after a sensor swap",
        },
    )
    after = wait_status(client, created["id"], "completed")["assignments"]
    assert [a["success"] for a in after[:18]] == [a["success"] for a in before[:18]]
    instance = catalog.scenario("baseline").instance
    rates = {r.name: dict(r.success) for r in instance.robots}
    rates["light"]["heavy"] = 0.95
    for a in after[18:]:
        task = instance.tasks[a["task_index"]]
        expected = sum(rates[a["robot"]][f] for f in task.features) / len(task.features)
        assert a["success"] == pytest.approx(expected)
    assert any(
        a["robot"] == "light" and "heavy" in instance.tasks[a["task_index"]].features
        for a in after[18:]
    )


def test_robot_available_brings_a_robot_back_for_the_unpinned_tasks(client: TestClient) -> None:
    parent = completed_run(client)
    down = revise(client, parent, {"changes": [HEAVY_DOWN], "pin": PIN_17, "reason": "fault"})
    wait_status(client, down["id"], "completed")
    back = revise(
        client,
        down["id"],
        {
            "changes": [{"type": "robot_available", "robot": "heavy"}],
            "pin": {"through_task_index": 20},
            "reason": "repaired",
        },
    )
    state = wait_status(client, back["id"], "completed")
    assert state["revision"] == 2
    assert any(a["robot"] == "heavy" for a in state["assignments"][21:])
    lineage = client.get(f"/runs/{parent}/revisions").json()
    assert [r["id"] for r in lineage] == [parent, down["id"], back["id"]]
    assert [r["reason"] for r in lineage] == [None, "fault", "repaired"]
    assert client.get(f"/runs/{back['id']}/trace/verify").json()["ok"] is True


def test_pins_that_break_the_cap_name_the_max_deviation_that_would_do(
    client: TestClient,
) -> None:
    parent = completed_run(client, {**BASELINE, "mode": "success_focused"})
    response = client.post(
        f"/runs/{parent}/revisions",
        json={
            "changes": [{"type": "set_mode", "mode": "aggressive_balance"}],
            "pin": "decided",
            "reason": "balance the fleet",
        },
    )
    assert response.status_code == 422, response.text
    detail = response.json()["detail"][0]
    assert detail["loc"] == ["body", "pin"] and "max_deviation" in detail["msg"]
    assert client.get(f"/runs/{parent}").json()["superseded_by"] is None


def battery(parent: str, ids: list[Any]) -> list[tuple[str, str, Any, int, str]]:
    """(endpoint, case, body, status, a field the error names)."""
    rev, exe = f"/runs/{parent}/revisions", f"/runs/{parent}/execution"
    ok = {"changes": [], "pin": "decided", "reason": "r"}
    return [
        (rev, "no body", None, 422, "body"),
        (rev, "not an object", [1], 422, "body"),
        (rev, "no reason", {"changes": []}, 422, "reason"),
        (rev, "empty reason", {**ok, "reason": ""}, 422, "reason"),
        (rev, "unknown field", {**ok, "colour": 1}, 422, "colour"),
        (rev, "unknown change type", {**ok, "changes": [{"type": "teleport"}]}, 422, "changes"),
        (
            rev,
            "unknown robot",
            {**ok, "changes": [{"type": "robot_unavailable", "robot": "x"}]},
            422,
            "robot",
        ),
        (
            rev,
            "contradictory pair",
            {**ok, "changes": [HEAVY_DOWN, {"type": "robot_available", "robot": "heavy"}]},
            422,
            "changes",
        ),
        (
            rev,
            "every robot unavailable",
            {
                **ok,
                "changes": [
                    {"type": "robot_unavailable", "robot": r} for r in ("light", "medium", "heavy")
                ],
            },
            422,
            "changes",
        ),
        (
            rev,
            "rate above 1",
            {**ok, "changes": [{"type": "set_rates", "robot": "light", "success": {"heavy": 1.5}}]},
            422,
            "success",
        ),
        (
            rev,
            "rate for unknown feature",
            {
                **ok,
                "changes": [{"type": "set_rates", "robot": "light", "success": {"flying": 0.5}}],
            },
            422,
            "flying",
        ),
        (
            rev,
            "added robot already there",
            {
                **ok,
                "changes": [
                    {
                        "type": "add_robot",
                        "robot": {
                            "name": "light",
                            "success": {"heavy": 1, "careful": 1, "dexterous": 1},
                        },
                    }
                ],
            },
            422,
            "name",
        ),
        (
            rev,
            "added robot misses a feature",
            {
                **ok,
                "changes": [
                    {"type": "add_robot", "robot": {"name": "new", "success": {"heavy": 0.5}}}
                ],
            },
            422,
            "success",
        ),
        (
            rev,
            "added task id taken",
            {
                **ok,
                "pin": PIN_17,
                "changes": [
                    {"type": "add_tasks", "tasks": [{"id": ids[30], "features": ["heavy"]}]}
                ],
            },
            422,
            "id",
        ),
        (
            rev,
            "added task unknown feature",
            {
                **ok,
                "pin": PIN_17,
                "changes": [{"type": "add_tasks", "tasks": [{"id": "N", "features": ["flying"]}]}],
            },
            422,
            "changes",
        ),
        (
            rev,
            "bad position",
            {
                **ok,
                "changes": [
                    {
                        "type": "add_tasks",
                        "tasks": [{"id": "N", "features": ["heavy"]}],
                        "position": "middle",
                    }
                ],
            },
            422,
            "position",
        ),
        (
            rev,
            "remove unknown task",
            {**ok, "pin": PIN_17, "changes": [{"type": "remove_tasks", "task_ids": ["nope"]}]},
            422,
            "task_ids",
        ),
        (
            rev,
            "added and removed",
            {
                **ok,
                "pin": PIN_17,
                "changes": [
                    {"type": "add_tasks", "tasks": [{"id": "N", "features": ["heavy"]}]},
                    {"type": "remove_tasks", "task_ids": ["N"]},
                ],
            },
            422,
            "changes",
        ),
        (
            rev,
            "unknown mode",
            {**ok, "changes": [{"type": "set_mode", "mode": "fast"}]},
            422,
            "mode",
        ),
        (
            rev,
            "negative cap",
            {**ok, "changes": [{"type": "set_mode", "mode": "balanced", "max_deviation": -1}]},
            422,
            "max_deviation",
        ),
        (rev, "unknown pin rule", {**ok, "pin": "everything"}, 422, "pin"),
        (rev, "pin past the queue", {**ok, "pin": {"through_task_index": 99}}, 422, "pin"),
        (rev, "pin unknown task", {**ok, "pin": {"task_ids": ["nope"]}}, 422, "pin"),
        (rev, "unknown reasoner", {**ok, "reasoner": "oracle"}, 422, "reasoner"),
        (rev, "replay reasoner", {**ok, "reasoner": "replay"}, 422, "reasoner"),
        ("/runs/nope/revisions", "unknown run", ok, 404, "run_id"),
        (exe, "no updates", {"updates": []}, 422, "updates"),
        (exe, "bad state", {"updates": [{"task_id": ids[0], "state": "paused"}]}, 422, "state"),
        (
            exe,
            "bad time",
            {"updates": [{"task_id": ids[0], "state": "done", "at": "noon"}]},
            422,
            "at",
        ),
        (exe, "unknown task", {"updates": [{"task_id": "nope", "state": "done"}]}, 422, "task_id"),
        (
            exe,
            "task id of the wrong type",
            {"updates": [{"task_id": True, "state": "done"}]},
            422,
            "task_id",
        ),
        (
            "/runs/nope/execution",
            "unknown run",
            {"updates": [{"task_id": 0, "state": "done"}]},
            404,
            "run_id",
        ),
    ]


def test_bad_input_battery(client: TestClient) -> None:
    parent = completed_run(client)
    ids = [a["task_id"] for a in assignments(client, parent)]
    runs_before = len(client.get("/runs").json())
    cases = battery(parent, ids)
    assert len(cases) >= 30
    for url, case, body, status, field in cases:
        response = client.post(url, json=body) if body is not None else client.post(url)
        assert response.status_code == status, (case, response.text)
        detail = response.json()["detail"]
        assert any(field in [str(p) for p in d["loc"]] or field in d["msg"] for d in detail), (
            case,
            detail,
        )
    # Never a half-written revision: no run was added, the parent names no revision.
    assert len(client.get("/runs").json()) == runs_before
    parent_state = client.get(f"/runs/{parent}").json()
    assert parent_state["superseded_by"] is None and parent_state["status"] == "completed"
    assert all(a.get("execution") is None for a in parent_state["assignments"])


def test_the_cap_rule_is_inherited(client: TestClient) -> None:
    explicit = completed_run(client, {**BASELINE, "max_deviation": 5})
    kept = revise(client, explicit, {"changes": [HEAVY_DOWN], "pin": PIN_17, "reason": "x"})
    assert client.get(f"/runs/{kept['id']}").json()["max_deviation"] == 5
    default = completed_run(client)
    recomputed = revise(client, default, {"changes": [HEAVY_DOWN], "pin": PIN_17, "reason": "x"})
    state = wait_status(client, recomputed["id"], "completed")
    parent = client.get(f"/runs/{default}").json()
    on_heavy = sum(a["robot"] == "heavy" for a in parent["assignments"][:18])
    w = (36 - on_heavy) / 2  # pins on heavy count for success, not for the balance
    assert state["max_deviation"] == math.ceil(w / 3)  # balanced: ceil(W/3) for the new W
    uncapped = revise(
        client,
        recomputed["id"],
        {
            "changes": [{"type": "set_mode", "mode": "balanced", "max_deviation": None}],
            "pin": "decided",
            "reason": "no cap",
        },
    )
    assert client.get(f"/runs/{uncapped['id']}").json()["max_deviation"] is None
