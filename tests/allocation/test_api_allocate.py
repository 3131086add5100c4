"""POST /allocate: the happy paths, and the exact optima of the baseline scenario."""

from __future__ import annotations

import threading
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr

from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply, good_responder
from tests.support.clients import ClientFactory
from tests.support.polling import eventually

ROBOTS: list[dict[str, Any]] = [
    {"name": "arm", "label": "Precision Arm", "success": {"dexterous": 0.9, "heavy": 0.3}},
    {"name": "lifter", "success": {"dexterous": 0.4, "heavy": 0.95}},
]
TASKS: list[dict[str, Any]] = [
    {"id": 1, "name": "Lift beam", "features": ["heavy"]},
    {"id": 2, "name": "Weld seam", "features": ["dexterous"]},
    {"id": 3, "name": "Carry frame", "features": ["heavy", "dexterous"]},
    {"id": 4, "name": "Drill", "features": ["dexterous"]},
    {"id": 5, "name": "Stack", "features": ["heavy"]},
]


def post(client: TestClient, body: dict[str, Any]) -> dict[str, Any]:
    r = client.post("/allocate", json=body)
    assert r.status_code == 200, r.text
    return r.json()


@pytest.mark.parametrize("solver", ["dp", "optimal"])
@pytest.mark.parametrize(
    ("mode", "cap", "expected"),
    [
        ("success_focused", None, 0.830556),
        ("balanced", None, 0.786111),
        ("aggressive_balance", 1, 0.769444),
    ],
)
def test_baseline_exact_optima(
    client: TestClient, solver: str, mode: str, cap: int | None, expected: float
) -> None:
    body: dict[str, Any] = {"solver": solver, "scenario": "baseline", "mode": mode}
    if cap is not None:
        body["max_deviation"] = cap
    out = post(client, body)
    assert out["metrics"]["expected_success"] == pytest.approx(expected, abs=1e-6)
    assert out["solver"] == solver and out["mode"] == mode


def test_response_shape_and_consistency(client: TestClient) -> None:
    out = post(client, {"solver": "greedy", "scenario": "baseline"})
    assert set(out) == {
        "solver",
        "mode",
        "max_deviation",
        "assignments",
        "metrics",
        "usage",
        "elapsed_ms",
    }
    assert out["mode"] == "balanced" and out["max_deviation"] == 4
    assert len(out["assignments"]) == 36
    assert out["assignments"][0] == {
        "task_id": 0,
        "task_name": "Stop",
        "robot": "light",
        "success": pytest.approx(0.8),
    }
    m = out["metrics"]
    assert set(m) == {
        "expected_success",
        "balance_score",
        "max_deviation",
        "imbalance_severity",
        "workload",
        "feature_success",
        "jain_index",
        "simulated_completion",
    }
    counts = {name: 0 for name in ("light", "medium", "heavy")}
    for a in out["assignments"]:
        counts[a["robot"]] += 1
    assert m["workload"] == counts
    assert all(8 <= n <= 16 for n in counts.values())  # W = 12, cap 4
    es = sum(a["success"] for a in out["assignments"]) / 36
    assert m["expected_success"] == pytest.approx(es)
    assert set(m["feature_success"]) == {"heavy", "dexterous", "careful"}
    sim = m["simulated_completion"]
    assert sim["trials"] > 0 and sim["ci95"][0] <= sim["mean"] <= sim["ci95"][1]
    assert out["usage"] == {"llm_calls": 0, "input_tokens": 0, "output_tokens": 0}
    assert out["elapsed_ms"] >= 0


@pytest.mark.parametrize(
    ("mode", "override", "effective"),
    [
        ("success_focused", None, None),
        ("balanced", None, 4),
        ("aggressive_balance", None, 1),
        ("balanced", 2, 2),
        ("success_focused", 0, 0),
    ],
)
def test_effective_cap_is_reported(
    client: TestClient, mode: str, override: int | None, effective: int | None
) -> None:
    body: dict[str, Any] = {"solver": "optimal", "scenario": "baseline", "mode": mode}
    if override is not None:
        body["max_deviation"] = override
    out = post(client, body)
    assert out["max_deviation"] == effective
    if effective is not None:
        assert out["metrics"]["max_deviation"] <= effective


def test_exact_solvers_agree_on_a_small_custom_instance(client: TestClient) -> None:
    results = {
        solver: post(
            client, {"solver": solver, "tasks": TASKS, "robots": ROBOTS, "mode": "balanced"}
        )
        for solver in ("brute_force", "dp", "optimal")
    }
    es = {s: r["metrics"]["expected_success"] for s, r in results.items()}
    assert es["brute_force"] == pytest.approx(es["dp"]) == pytest.approx(es["optimal"])
    assert results["brute_force"]["assignments"] == results["dp"]["assignments"]
    assert [a["task_id"] for a in results["dp"]["assignments"]] == [1, 2, 3, 4, 5]
    # W = 2.5, default cap ceil(5/6) = 1: loads within [2, 3]
    assert sorted(results["dp"]["metrics"]["workload"].values()) == [2, 3]


def test_custom_tasks_accept_teach_keys_and_string_ids(client: TestClient) -> None:
    tasks = [
        {
            "action_id": 200,
            "action_name": "Pickup",
            "action_type": "ObjectInteraction",
            "features": ["heavy"],
            "pose_delta": [0, 0, 0],
        },  # extra TEACh keys are ignored
        {"id": "weld-7", "name": "Weld seam", "features": ["dexterous"]},
        {"id": "drill", "features": ["dexterous"]},
    ]
    out = post(
        client,
        {
            "solver": "greedy",
            "tasks": tasks,
            "robots": ROBOTS,
            "mode": "success_focused",
            "seed": 7,
        },
    )
    assert [(a["task_id"], a["task_name"], a["robot"]) for a in out["assignments"]] == [
        (200, "Pickup", "lifter"),
        ("weld-7", "Weld seam", "arm"),
        ("drill", "drill", "arm"),
    ]
    assert out["max_deviation"] is None


def test_seed_makes_the_simulation_reproducible(client: TestClient) -> None:
    body = {"solver": "dp", "scenario": "baseline"}
    first = post(client, {**body, "seed": 3})["metrics"]["simulated_completion"]
    again = post(client, {**body, "seed": 3})["metrics"]["simulated_completion"]
    other = post(client, {**body, "seed": 4})["metrics"]["simulated_completion"]
    assert first == again
    assert first != other


def test_fractional_cap_and_any_feature_names(client: TestClient) -> None:
    robots = [{"name": f"r{i}", "success": {"paint": 0.1 * (i + 1)}} for i in range(3)]
    tasks = [{"id": i, "features": ["paint"]} for i in range(7)]
    out = post(
        client, {"solver": "optimal", "tasks": tasks, "robots": robots, "max_deviation": 0.7}
    )
    # W = 7/3: loads within [ceil(1.63), floor(3.03)] = [2, 3]
    assert out["max_deviation"] == pytest.approx(0.7)
    assert out["metrics"]["workload"] == {"r0": 2, "r1": 2, "r2": 3}


def test_a_long_solve_leaves_the_event_loop_free(make_client: ClientFactory) -> None:
    """The solve runs in the threadpool: /health answers while a long /allocate is solving.

    The solve is kept long by its reasoner: the fake Messages API holds its answers until
    /health has been asked, so "under way" is observed (the API got the solve's first
    call), not guessed from a sleep, and the solve cannot end too soon."""
    health_asked = threading.Event()

    def answer_after_health(request: dict[str, Any]) -> Reply:
        health_asked.wait(timeout=10)  # a blocked event loop shows as a failure, not a hang
        return good_responder(request)

    robots = [{"name": f"r{i}", "success": {"f": 0.2 * (i + 1)}} for i in range(4)]
    body = {
        "solver": "ltaa",
        "tasks": [{"id": i, "features": ["f"]} for i in range(3)],
        "robots": robots,
        "options": {"reasoner": "anthropic", "model": "claude-test"},
    }
    answered: list[int] = []
    with FakeMessagesAPI(default=answer_after_health) as api:
        client = make_client(
            anthropic_api_key=SecretStr("test-key"), anthropic_base_url=api.base_url
        )
        solving = threading.Thread(
            target=lambda: answered.append(client.post("/allocate", json=body).status_code)
        )
        solving.start()
        try:
            eventually(lambda: api.requests, what="the solve's first call to the Messages API")
            assert client.get("/health").status_code == 200
            assert answered == []  # /health did not wait for the solve
        finally:
            health_asked.set()
            solving.join()
    assert answered == [200]


def test_explicit_null_max_deviation_means_no_cap(client: TestClient) -> None:
    body = {"solver": "optimal", "scenario": "baseline", "mode": "balanced"}
    default = client.post("/allocate", json=body).json()
    uncapped = client.post("/allocate", json={**body, "max_deviation": None}).json()
    assert default["max_deviation"] == 4
    assert uncapped["max_deviation"] is None
    assert uncapped["metrics"]["expected_success"] == pytest.approx(0.830556, abs=1e-6)


def test_runs_offset_beyond_any_page_is_a_422_not_a_500(client: TestClient) -> None:
    response = client.get("/runs", params={"offset": 2**63})
    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["query", "offset"]
