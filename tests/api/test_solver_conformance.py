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
from app.solvers.registry import solver_names

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
