"""One contract, every solver: each registered method is held to the same checks.

Queue order kept, exactly one robot per task, the cap respected, and every reported
metric equal to the metric recomputed from the returned assignments.
"""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.domain.catalog import scenario
from app.domain.metrics import compute_metrics
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.solvers.registry import get_solver, solver_names

# Fast settings for the learners: conformance is about the contract, not their quality.
FAST_OPTIONS: dict[str, dict[str, Any]] = {
    "q_learning": {"episodes": 300},
    "dqn": {"timesteps": 600},
}

SMALL = {
    "tasks": [
        {"action_id": 10, "action_name": "Lift", "action_type": "Motion", "features": ["heavy"]},
        {"id": "weld-1", "name": "Weld seam", "features": ["careful", "dexterous"]},
        {"id": 3, "name": "Sweep", "features": ["dexterous"]},
        {"id": 4, "name": "Carry", "features": ["heavy", "careful"]},
        {"id": 5, "name": "Inspect", "features": ["careful"]},
        {"id": 6, "name": "Drill", "features": ["heavy", "dexterous"]},
    ],
    "robots": [
        {"name": "alpha", "success": {"heavy": 0.9, "careful": 0.4, "dexterous": 0.5}},
        {"name": "beta", "success": {"heavy": 0.3, "careful": 0.95, "dexterous": 0.8}},
    ],
}


def _cases() -> list[tuple[str, dict[str, Any]]]:
    cases = []
    for name in solver_names():
        for mode in Mode:
            cases.append((name, {**SMALL, "mode": mode.value}))
        if name != "brute_force":
            cases.append((name, {"scenario": "baseline", "mode": "balanced"}))
    return cases


@pytest.mark.parametrize(("solver", "body"), _cases())
def test_solver_meets_the_contract(client: TestClient, solver: str, body: dict[str, Any]) -> None:
    request = {**body, "solver": solver, "seed": 3, "options": FAST_OPTIONS.get(solver, {})}
    response = client.post("/allocate", json=request)
    assert response.status_code == 200, response.text
    data = response.json()

    if "scenario" in body:
        instance = scenario(body["scenario"]).instance
    else:
        from app.domain.serialize import instance_from_dict

        instance = instance_from_dict(
            {
                "tasks": [
                    {
                        "id": t.get("id", t.get("action_id")),
                        "name": t.get("name", t.get("action_name")),
                        "features": t["features"],
                    }
                    for t in body["tasks"]
                ],
                "robots": body["robots"],
            }
        )
    problem = Problem.build(instance, Mode(body["mode"]))

    # Queue order kept; exactly one robot per task.
    assert [a["task_id"] for a in data["assignments"]] == [t.id for t in instance.tasks]
    names = [r.name for r in instance.robots]
    assignment = [names.index(a["robot"]) for a in data["assignments"]]

    # The cap is respected and reported.
    metrics = compute_metrics(instance, assignment, seed=3)
    assert problem.cap.respected_by(list(metrics.workload.values()))
    assert data["max_deviation"] == problem.cap.max_deviation

    # Reported metrics equal metrics recomputed from the assignments.
    reported = data["metrics"]
    assert reported["expected_success"] == pytest.approx(metrics.expected_success, abs=1e-12)
    assert reported["balance_score"] == pytest.approx(metrics.balance_score, abs=1e-9)
    assert reported["max_deviation"] == pytest.approx(metrics.max_deviation, abs=1e-12)
    assert reported["imbalance_severity"] == metrics.imbalance_severity.value
    assert reported["workload"] == metrics.workload
    assert reported["feature_success"] == pytest.approx(metrics.feature_success, abs=1e-12)
    assert reported["jain_index"] == pytest.approx(metrics.jain_index, abs=1e-12)
    sim = reported["simulated_completion"]
    assert sim["mean"] == pytest.approx(metrics.simulated_completion.mean, abs=1e-12)
    assert sim["trials"] == metrics.simulated_completion.trials
    for a, t in zip(data["assignments"], range(instance.n_tasks), strict=True):
        assert a["success"] == pytest.approx(instance.success[t, assignment[t]], abs=1e-12)


# Pins (docs/living-plans.md#pins-in-allocate): on SMALL, "Weld seam" is fixed on alpha (its worse
# robot) and beta is unavailable after taking "Sweep"; on baseline the heavy robot breaks down after
# task 17.
BASELINE_TASKS = [t.id for t in scenario("baseline").instance.tasks]
PINNED_CASES: dict[str, dict[str, Any]] = {
    "small_pins": {
        **SMALL,
        "mode": "success_focused",
        "pinned": [{"task_id": "weld-1", "robot": "alpha"}, {"task_id": 6, "robot": "beta"}],
    },
    "small_unavailable": {
        **SMALL,
        "mode": "balanced",
        "max_deviation": 1,
        "pinned": [{"task_id": 3, "robot": "beta"}],
        "unavailable": ["beta"],
    },
    "baseline_heavy_down": {
        "scenario": "baseline",
        "mode": "balanced",
        "pinned": [
            {"task_id": tid, "robot": ("light", "medium", "heavy")[i % 3]}
            for i, tid in enumerate(BASELINE_TASKS[:18])
        ],
        "unavailable": ["heavy"],
    },
    "baseline_mostly_pinned": {
        "scenario": "baseline",
        "mode": "aggressive_balance",
        "pinned": [
            {"task_id": tid, "robot": ("light", "medium", "heavy")[i % 3]}
            for i, tid in enumerate(BASELINE_TASKS[:30])
        ],
        "unavailable": ["medium"],
    },
}


def _pinned_cases() -> list[Any]:
    cases = []
    for name in solver_names():
        for case, body in PINNED_CASES.items():
            if name in ("brute_force",) and case == "baseline_heavy_down":
                continue  # 2^18 free assignments: above brute force's limit
            cases.append(pytest.param(name, body, id=f"{name}-{case}"))
    return cases


def _instance_of(body: dict[str, Any]) -> Any:
    if "scenario" in body:
        return scenario(body["scenario"]).instance
    from app.allocation.schemas import InstanceRequest
    from app.allocation.service import resolve_instance

    return resolve_instance(
        InstanceRequest.model_validate({k: body[k] for k in ("tasks", "robots")})
    )


@pytest.mark.parametrize(("solver", "body"), _pinned_cases())
def test_solver_honours_pins(client: TestClient, solver: str, body: dict[str, Any]) -> None:
    request = {**body, "solver": solver, "seed": 3, "options": FAST_OPTIONS.get(solver, {})}
    response = client.post("/allocate", json=request)
    assert response.status_code == 200, response.text
    data = response.json()
    instance = _instance_of(body)
    names = [r.name for r in instance.robots]
    ids = [str(t.id) for t in instance.tasks]
    pins = {ids.index(str(p["task_id"])): names.index(p["robot"]) for p in body["pinned"]}
    off = [names.index(n) for n in body.get("unavailable", [])]
    problem = Problem.build(
        instance, Mode(body["mode"]), body.get("max_deviation"), pinned=pins, unavailable=off
    )

    assert [a["task_id"] for a in data["assignments"]] == [t.id for t in instance.tasks]
    assignment = [names.index(a["robot"]) for a in data["assignments"]]
    # Pinned tasks stay where they were pinned, marked; no new task goes to an unavailable robot.
    assert {t: assignment[t] for t in pins} == pins
    assert [a.get("pinned", False) for a in data["assignments"]] == [
        t in pins for t in range(len(ids))
    ]
    assert all(a["pinned"] is True for a in data["assignments"] if "pinned" in a)
    assert all(assignment[t] not in off for t in problem.free_tasks)

    # The cap of the available fleet is respected and reported.
    metrics = compute_metrics(instance, assignment, seed=3, scope=problem.balance_scope)
    assert problem.cap.respected_by(list(metrics.workload.values()))
    assert data["max_deviation"] == problem.cap.max_deviation
    reported = data["metrics"]
    assert reported["expected_success"] == pytest.approx(metrics.expected_success, abs=1e-12)
    assert reported["balance_score"] == pytest.approx(metrics.balance_score, abs=1e-9)
    assert reported["max_deviation"] == pytest.approx(metrics.max_deviation, abs=1e-12)
    assert reported["imbalance_severity"] == metrics.imbalance_severity.value
    assert reported["workload"] == metrics.workload
    assert reported["jain_index"] == pytest.approx(metrics.jain_index, abs=1e-12)

    # Exact solvers return the optimum given the pins.
    if solver in ("brute_force", "dp", "optimal"):
        optimum = compute_metrics(
            instance, get_solver("optimal").solve(problem).assignment, trials=1
        ).expected_success
        assert metrics.expected_success == pytest.approx(optimum, abs=1e-9)


# docs/allocation.md#teams: skills restrict who may take what. The rates make the forbidden
# robots tempting (alpha is the best at careful work, but careful is not among its skills).
RESTRICTED: dict[str, Any] = {
    "tasks": SMALL["tasks"],
    "robots": [
        {
            "name": "alpha",
            "success": {"heavy": 0.9, "careful": 0.99, "dexterous": 0.5},
            "skills": ["heavy", "dexterous"],
        },
        {
            "name": "beta",
            "success": {"heavy": 0.95, "careful": 0.6, "dexterous": 0.8},
            "skills": ["careful", "dexterous"],
        },
        {"name": "gamma", "success": {"heavy": 0.3, "careful": 0.3, "dexterous": 0.3}},
    ],
}


@pytest.mark.parametrize("solver", solver_names())
@pytest.mark.parametrize("mode", ["success_focused", "aggressive_balance"])
def test_solver_honours_skills(client: TestClient, solver: str, mode: str) -> None:
    request = {
        **RESTRICTED,
        "mode": mode,
        "solver": solver,
        "seed": 3,
        "options": FAST_OPTIONS.get(solver, {}),
    }
    response = client.post("/allocate", json=request)
    assert response.status_code == 200, response.text
    data = response.json()
    skills = {r["name"]: set(r.get("skills", r["success"])) for r in RESTRICTED["robots"]}
    for task, a in zip(RESTRICTED["tasks"], data["assignments"], strict=True):
        assert set(task["features"]) <= skills[a["robot"]], (task, a["robot"])
    instance = _instance_of(RESTRICTED)
    problem = Problem.build(instance, Mode(mode))
    assert problem.cap.respected_by(list(data["metrics"]["workload"].values()))
    if solver in ("brute_force", "dp", "optimal"):
        best = get_solver("optimal").solve(problem).assignment
        optimum = compute_metrics(instance, best, trials=1).expected_success
        assert data["metrics"]["expected_success"] == pytest.approx(optimum, abs=1e-9)
