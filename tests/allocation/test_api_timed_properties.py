"""Random small timed sites through POST /allocate (hypothesis): never a 5xx; every schedule
answered is feasible by the test's own reading of docs/schedules.md#a-schedule-and-its-check exactly
when the answer lists no violation; and what `schedule` calls optimal is the exhaustive optimum."""

from __future__ import annotations

import math
from typing import Any

import pytest
from fastapi.testclient import TestClient
from hypothesis import HealthCheck, given, settings
from hypothesis import strategies as st

from tests.allocation.test_api_timed import success_matrix
from tests.support.timed_checks import best_makespan, feasibility_errors, loads_within_cap

ROBOT_NAMES = ("a", "b")
RATES = st.sampled_from([0.3, 0.5, 0.65, 0.8, 0.9])


@st.composite
def timed_bodies(draw: st.DrawFn) -> dict[str, Any]:
    n = draw(st.integers(2, 5))
    zoned = draw(st.booleans())
    zones = ["A", "B", "C"]
    tasks: list[dict[str, Any]] = []
    for i in range(n):
        task: dict[str, Any] = {
            "id": f"t{i}",
            "features": draw(st.sampled_from([["heavy"], ["dexterous"], ["heavy", "dexterous"]])),
            "after": draw(st.lists(st.sampled_from([f"t{k}" for k in range(i)]), unique=True))
            if i
            else [],
        }
        if draw(st.booleans()):
            task["duration"] = draw(st.integers(1, 30))
        else:  # a map, leaving a robot out now and then
            names = draw(st.sampled_from([ROBOT_NAMES, ("a",), ("b",)]))
            task["duration"] = {r: draw(st.integers(1, 30)) for r in names}
        if zoned:
            task["zone"] = draw(st.sampled_from(zones))
        if draw(st.integers(0, 3)) == 0:
            task["release"] = draw(st.integers(0, 40))
        if draw(st.integers(0, 3)) == 0:
            task["deadline"] = draw(st.integers(20, 160))
        tasks.append(task)
    robots: list[dict[str, Any]] = []
    for name in ROBOT_NAMES:
        robot: dict[str, Any] = {
            "name": name,
            "success": {"heavy": draw(RATES), "dexterous": draw(RATES)},
        }
        if zoned and draw(st.booleans()):
            robot["zone"] = draw(st.sampled_from(zones))
        if draw(st.booleans()):
            start = draw(st.integers(0, 20))
            robot["available"] = [start, start + draw(st.integers(40, 200))]
        robots.append(robot)
    body: dict[str, Any] = {
        "tasks": tasks,
        "robots": robots,
        "mode": draw(st.sampled_from(["success_focused", "balanced", "aggressive_balance"])),
        "objective": draw(st.sampled_from(["success_then_makespan", "makespan"])),
    }
    if zoned:
        body["travel"] = {
            "A": {"B": draw(st.integers(1, 9)), "C": draw(st.integers(1, 9))},
            "B": {"C": draw(st.integers(1, 9))},
        }
    return body


def _loads(answer: dict[str, Any], n_tasks: int) -> tuple[int, int] | None:
    cap = answer["max_deviation"]
    if cap is None:
        return None
    w = n_tasks / len(ROBOT_NAMES)
    return math.ceil(w - cap - 1e-9), math.floor(w + cap + 1e-9)


@pytest.mark.filterwarnings("ignore::hypothesis.errors.NonInteractiveExampleWarning")
@settings(
    max_examples=60,
    deadline=None,
    derandomize=True,
    suppress_health_check=[HealthCheck.function_scoped_fixture, HealthCheck.too_slow],
)
@given(body=timed_bodies())
def test_random_timed_sites_get_feasible_schedules_or_a_422(
    client: TestClient, body: dict[str, Any]
) -> None:
    exact = client.post(
        "/allocate", json={**body, "solver": "schedule", "options": {"time_limit_s": 5}}
    )
    assert exact.status_code in (200, 422), exact.text
    if exact.status_code == 422:
        assert exact.json()["detail"][0]["loc"][0] == "body"
        return
    answer = exact.json()
    assert feasibility_errors(body, answer["schedule"]) == []
    assert answer["schedule_violations"] == [] and loads_within_cap(body, answer)
    es, makespan = best_makespan(
        body,
        success_matrix(body),
        _loads(answer, len(body["tasks"])),
        success_first=body["objective"] == "success_then_makespan",
    )
    assert answer["bound"] <= makespan + 1e-6 <= answer["schedule"]["makespan"] + 2e-6
    if answer["status"] == "optimal":
        assert answer["schedule"]["makespan"] == pytest.approx(makespan)
    if body["objective"] == "success_then_makespan":
        assert answer["metrics"]["expected_success"] == pytest.approx(es)

    greedy = client.post("/allocate", json={**body, "solver": "greedy"})
    assert greedy.status_code == 200, greedy.text
    other = greedy.json()
    if other.get("schedule") is not None:
        broken = feasibility_errors(body, other["schedule"])
        assert (broken == []) == (other["schedule_violations"] == []), (broken, other)
