"""POST /allocate with team tasks and skills (docs/allocation.md#teams): the answer's teams,
every method's answer or refusal, and each bad input a 422 naming the task and feature."""

from __future__ import annotations

import copy
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.solvers.registry import solver_names
from tests.api.test_api_bad_requests import assert_error_shape, assert_names
from tests.solvers.test_solver_conformance import FAST_OPTIONS

TEAM_BODY: dict[str, Any] = {
    "tasks": [
        {"id": "beam", "name": "Lift beam", "team": {"heavy": 2}},
        {"id": "panel", "name": "Fix panel", "team": {"heavy": 1, "careful": 1}},
        {"id": "sweep", "name": "Sweep", "features": ["careful"]},
        {"id": "carry", "name": "Carry", "features": ["heavy"]},
    ],
    "robots": [
        {"name": "crane", "success": {"heavy": 0.9, "careful": 0.2}, "skills": ["heavy"]},
        {"name": "arm", "success": {"heavy": 0.3, "careful": 0.95}},
        {"name": "lifter", "success": {"heavy": 0.8, "careful": 0.4}},
    ],
}


def body(**changes: Any) -> dict[str, Any]:
    out = copy.deepcopy(TEAM_BODY)
    out.update(changes)
    return out


def test_optimal_answers_whole_teams(client: TestClient) -> None:
    r = client.post("/allocate", json=body(solver="optimal", mode="success_focused"))
    assert r.status_code == 200, r.text
    data = r.json()
    beam, panel, sweep, _ = data["assignments"]
    assert beam["team"] == [
        {"robot": "crane", "feature": "heavy"},
        {"robot": "lifter", "feature": "heavy"},
    ]
    assert beam["robot"] == "crane"  # the member covering the first unit
    assert beam["success"] == pytest.approx(0.85)
    assert [m["feature"] for m in panel["team"]] == ["heavy", "careful"]
    assert panel["robot"] == panel["team"][0]["robot"]
    assert "team" not in sweep  # one-robot tasks answer as before
    loads = {"crane": 0, "arm": 0, "lifter": 0}
    for a in data["assignments"]:
        for member in a.get("team") or [{"robot": a["robot"]}]:
            loads[member["robot"]] += 1
    assert data["metrics"]["workload"] == loads  # a team task counts once per member
    assert sum(loads.values()) == 6


@pytest.mark.parametrize("solver", solver_names())
def test_every_method_answers_valid_teams_or_refuses(client: TestClient, solver: str) -> None:
    request = body(solver=solver, mode="balanced", seed=1, options=FAST_OPTIONS.get(solver, {}))
    r = client.post("/allocate", json=request)
    if r.status_code == 422:
        (item,) = assert_error_shape(r.json())
        assert item["loc"] == ["body", "tasks", 0, "team"]
        assert "'optimal'" in item["msg"] and solver in item["msg"]
        return
    assert r.status_code == 200, r.text
    skills = {"crane": {"heavy"}}
    loads = {"crane": 0, "arm": 0, "lifter": 0}
    for task, a in zip(TEAM_BODY["tasks"], r.json()["assignments"], strict=True):
        members = a.get("team") or [{"robot": a["robot"], "feature": None}]
        robots = [m["robot"] for m in members]
        assert len(robots) == len(set(robots)), "members are distinct"
        if "team" in task:
            units = [f for f, c in task["team"].items() for _ in range(c)]
            assert [m["feature"] for m in members] == units, "every unit covered, in key order"
            assert all(m["feature"] in skills.get(m["robot"], {m["feature"]}) for m in members)
        else:
            assert set(task["features"]) <= skills.get(a["robot"], set(task["features"]))
        for name in robots:
            loads[name] += 1
    # balanced: W = 6 / 3 = 2, cap ceil(2/3) = 1: loads within [1, 3]
    assert all(1 <= x <= 3 for x in loads.values()), loads


def _team_task(**changes: Any) -> list[dict[str, Any]]:
    return [{**TEAM_BODY["tasks"][0], **changes}, *TEAM_BODY["tasks"][1:]]


BAD: list[tuple[str, dict[str, Any], list[Any], list[str]]] = [
    ("count_below_one", body(tasks=_team_task(team={"heavy": 0})), ["team", "heavy"], ["beam"]),
    (
        "feature_no_robot_rates",
        body(tasks=_team_task(team={"heavy": 1, "welding": 1})),
        ["team", "welding"],
        ["beam", "welding"],
    ),
    (
        "more_robots_than_can_cover",
        body(tasks=_team_task(team={"careful": 3})),
        ["team", "careful"],
        ["beam", "'careful'", "only 2 can (arm, lifter)"],
    ),
    (
        "no_eligible_robot",
        body(
            tasks=[{"id": "weld", "features": ["careful", "heavy"]}],
            robots=[
                {"name": "a", "success": {"heavy": 0.9, "careful": 0.2}, "skills": ["heavy"]},
                {"name": "b", "success": {"heavy": 0.2, "careful": 0.9}, "skills": ["careful"]},
            ],
        ),
        ["features"],
        ["weld", "no eligible robot", "'careful'"],
    ),
    (
        "team_with_duration_map",
        body(tasks=_team_task(duration={"crane": 10, "lifter": 12})),
        ["duration"],
        ["beam", "team task", "per-robot map"],
    ),
    (
        "features_disagree_with_team",
        body(tasks=_team_task(features=["careful"])),
        ["features"],
        ["beam", "'heavy'", "disagree"],
    ),
    (
        "skill_not_rated",
        body(robots=[{**TEAM_BODY["robots"][0], "skills": ["welding"]}, *TEAM_BODY["robots"][1:]]),
        ["skills"],
        ["crane", "welding"],
    ),
]


@pytest.mark.parametrize(
    ("request_body", "loc", "words"), [c[1:] for c in BAD], ids=[c[0] for c in BAD]
)
def test_bad_team_inputs_name_the_task_and_feature(
    client: TestClient, request_body: dict[str, Any], loc: list[Any], words: list[str]
) -> None:
    r = client.post("/allocate", json={**request_body, "solver": "optimal"})
    assert r.status_code == 422, r.text
    detail = assert_error_shape(r.json())
    where = ["body", "robots", 0] if loc == ["skills"] else ["body", "tasks", 0]
    assert_names(detail, [*where, *loc], None)
    for word in words:
        assert any(word in d["msg"] for d in detail), (word, detail)


def test_a_task_needs_features_or_a_team(client: TestClient) -> None:
    tasks = [{"id": "x"}, *TEAM_BODY["tasks"][1:]]
    r = client.post("/allocate", json=body(tasks=tasks, solver="optimal"))
    assert r.status_code == 422
    assert "features" in r.text and "team" in r.text


def test_a_durable_untimed_team_run_is_accepted(client: TestClient) -> None:
    """docs/allocation.md#teams: the LTAA graph forms teams (tests/runs/test_api_team_runs.py)."""
    r = client.post("/runs", json={**copy.deepcopy(TEAM_BODY), "reasoner": "rules"})
    assert r.status_code == 202, r.text
