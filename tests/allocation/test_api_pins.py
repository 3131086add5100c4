"""`pinned` and `unavailable` on POST /allocate (docs/living-plans.md#pins-in-allocate)."""

from __future__ import annotations

from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.domain.catalog import scenario
from tests.api.test_api_bad_requests import assert_error_shape, assert_names

IDS = [t.id for t in scenario("baseline").instance.tasks]
FLEET = ("light", "medium", "heavy")
# The paper's resume point: tasks 0-17 done round-robin, then the heavy robot breaks down.
ROUND_ROBIN = [{"task_id": tid, "robot": FLEET[i % 3]} for i, tid in enumerate(IDS[:18])]
HEAVY_DOWN: dict[str, Any] = {
    "scenario": "baseline",
    "mode": "balanced",
    "pinned": ROUND_ROBIN,
    "unavailable": ["heavy"],
}
ON_LIGHT = [{"task_id": tid, "robot": "light"} for tid in IDS[:18]]


def body(**changes: Any) -> dict[str, Any]:
    return {"solver": "optimal", "scenario": "baseline", **changes}


def test_heavy_down_keeps_the_pins_and_balances_the_rest(client: TestClient) -> None:
    r = client.post("/allocate", json=body(**HEAVY_DOWN))
    assert r.status_code == 200, r.text
    data = r.json()
    rows = data["assignments"]
    assert [a["robot"] for a in rows[:18]] == [FLEET[i % 3] for i in range(18)]
    assert all(a["pinned"] is True for a in rows[:18])
    assert not any("pinned" in a for a in rows[18:])  # the field is there only when true
    assert all(a["robot"] != "heavy" for a in rows[18:])
    # W = (18 free + 12 pinned on light and medium) / 2 = 15; the mode default cap is 5.
    assert data["max_deviation"] == 5
    workload = data["metrics"]["workload"]
    assert workload["heavy"] == 6 and 10 <= workload["light"] <= 20
    assert workload["light"] + workload["medium"] == 30
    dev = max(abs(workload["light"] - 15), abs(workload["medium"] - 15))
    assert data["metrics"]["max_deviation"] == dev
    assert data["metrics"]["balance_score"] == pytest.approx(100 * (1 - dev / 15))


def test_every_exact_solver_finds_the_same_optimum_given_the_pins(client: TestClient) -> None:
    pins = {
        **HEAVY_DOWN,
        "pinned": ROUND_ROBIN + [{"task_id": IDS[t], "robot": "medium"} for t in range(18, 28)],
    }
    es = {
        solver: client.post("/allocate", json=body(**pins, solver=solver)).json()["metrics"][
            "expected_success"
        ]
        for solver in ("optimal", "dp", "brute_force")
    }
    assert es["dp"] == pytest.approx(es["optimal"], abs=1e-12)
    assert es["brute_force"] == pytest.approx(es["optimal"], abs=1e-12)


def test_robots_may_be_named_by_label_and_task_ids_as_text(client: TestClient) -> None:
    r = client.post(
        "/allocate",
        json=body(pinned=[{"task_id": "300", "robot": "Light Robot"}], unavailable=["Heavy Robot"]),
    )
    assert r.status_code == 200, r.text
    rows = {a["task_id"]: a for a in r.json()["assignments"]}
    assert rows[300]["robot"] == "light" and rows[300]["pinned"]
    assert all(a["robot"] != "heavy" for a in rows.values())


def test_without_pins_nothing_changes(client: TestClient) -> None:
    plain = client.post("/allocate", json=body()).json()
    empty = client.post("/allocate", json=body(pinned=[], unavailable=[])).json()
    for data in (plain, empty):
        data.pop("elapsed_ms")
    assert plain == empty
    assert not any("pinned" in a for a in plain["assignments"])


def test_pins_that_break_the_cap_say_which_max_deviation_would_do(client: TestClient) -> None:
    r = client.post("/allocate", json=body(pinned=ON_LIGHT))
    assert r.status_code == 422
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body", "pinned"] and item["type"] == "infeasible_cap"
    # W = 12, balanced default cap 4: light may hold at most 16 tasks, the pins give it 18.
    assert "18 tasks on robot 'light'" in item["msg"]
    assert "smallest max_deviation that admits a completion" in item["msg"]
    assert item["msg"].endswith(" 6")
    ok = client.post("/allocate", json=body(pinned=ON_LIGHT, max_deviation=6))
    assert ok.status_code == 200, ok.text
    assert ok.json()["metrics"]["workload"]["light"] == 18


def test_unavailable_robots_can_make_an_explicit_cap_infeasible(client: TestClient) -> None:
    # 36 tasks over 2 robots is W = 18 exactly; 35 (one pinned on the broken robot) is 17.5.
    pins = [{"task_id": IDS[0], "robot": "heavy"}]
    r = client.post("/allocate", json=body(pinned=pins, unavailable=["heavy"], max_deviation=0))
    assert r.status_code == 422
    (item,) = assert_error_shape(r.json())
    assert item["loc"] == ["body", "max_deviation"] and item["type"] == "infeasible_cap"
    assert "target load 17.5" in item["msg"] and item["msg"].endswith(" 0.5")


def test_brute_force_counts_only_the_free_space(client: TestClient) -> None:
    many = [{"task_id": tid, "robot": FLEET[i % 3]} for i, tid in enumerate(IDS[:23])]
    refused = client.post("/allocate", json=body(solver="brute_force", pinned=many))
    assert refused.status_code == 422
    (item,) = assert_error_shape(refused.json())
    assert item["type"] == "too_large" and "3^12 = 531,441" in item["msg"]
    assert "free tasks on available robots" in item["msg"]
    more = [{"task_id": tid, "robot": FLEET[i % 3]} for i, tid in enumerate(IDS[:24])]
    assert client.post("/allocate", json=body(solver="brute_force", pinned=more)).status_code == 200


def test_runs_do_not_take_pins_yet(client: TestClient) -> None:
    r = client.post("/runs", json={"scenario": "baseline", "pinned": ON_LIGHT[:1]})
    assert r.status_code == 422
    assert_names(assert_error_shape(r.json()), ["body", "pinned"], None)


PIN = {"task_id": IDS[0], "robot": "light"}
# (case id, body changes, expected loc, substring of the message or None)
BAD: list[tuple[str, dict[str, Any], list[Any], str | None]] = [
    (
        "unknown_task",
        {"pinned": [{"task_id": 999, "robot": "light"}]},
        ["body", "pinned", 0, "task_id"],
        "999",
    ),
    (
        "unknown_task_text",
        {"pinned": [PIN, {"task_id": "weld", "robot": "light"}]},
        ["body", "pinned", 1, "task_id"],
        "'weld'",
    ),
    (
        "unknown_robot",
        {"pinned": [{"task_id": IDS[0], "robot": "crane"}]},
        ["body", "pinned", 0, "robot"],
        "crane",
    ),
    (
        "pinned_twice",
        {"pinned": [PIN, {"task_id": IDS[0], "robot": "heavy"}]},
        ["body", "pinned", 1, "task_id"],
        "pinned twice",
    ),
    (
        "pinned_twice_as_text",
        {"pinned": [PIN, {"task_id": str(IDS[0]), "robot": "light"}]},
        ["body", "pinned", 1, "task_id"],
        "pinned twice",
    ),
    (
        "unknown_unavailable",
        {"unavailable": ["light", "crane"]},
        ["body", "unavailable", 1],
        "crane",
    ),
    (
        "unavailable_twice",
        {"unavailable": ["heavy", "heavy"]},
        ["body", "unavailable", 1],
        "listed twice",
    ),
    (
        "unavailable_twice_by_label",
        {"unavailable": ["heavy", "Heavy Robot"]},
        ["body", "unavailable", 1],
        "listed twice",
    ),
    ("no_robot_left", {"unavailable": list(FLEET)}, ["body", "unavailable"], "no robot is left"),
    (
        "pins_break_cap",
        {"pinned": ON_LIGHT, "mode": "aggressive_balance"},
        ["body", "pinned"],
        "max_deviation",
    ),
    ("pinned_not_list", {"pinned": {"task_id": 0, "robot": "light"}}, ["body", "pinned"], None),
    ("pin_not_object", {"pinned": ["light"]}, ["body", "pinned", 0], None),
    ("pin_without_robot", {"pinned": [{"task_id": IDS[0]}]}, ["body", "pinned", 0, "robot"], None),
    ("pin_without_task", {"pinned": [{"robot": "light"}]}, ["body", "pinned", 0, "task_id"], None),
    ("pin_extra_key", {"pinned": [{**PIN, "at": 3}]}, ["body", "pinned", 0, "at"], None),
    (
        "pin_task_bool",
        {"pinned": [{"task_id": True, "robot": "light"}]},
        ["body", "pinned", 0, "task_id"],
        "boolean",
    ),
    (
        "pin_robot_empty",
        {"pinned": [{"task_id": IDS[0], "robot": ""}]},
        ["body", "pinned", 0, "robot"],
        None,
    ),
    (
        "pin_robot_number",
        {"pinned": [{"task_id": IDS[0], "robot": 2}]},
        ["body", "pinned", 0, "robot"],
        None,
    ),
    ("unavailable_not_list", {"unavailable": "heavy"}, ["body", "unavailable"], None),
    ("unavailable_number", {"unavailable": [1]}, ["body", "unavailable", 0], None),
    ("unavailable_null", {"unavailable": None}, ["body", "unavailable"], None),
    ("unavailable_nul", {"unavailable": ["he\x00avy"]}, ["body", "unavailable", 0], "NUL"),
]


@pytest.mark.parametrize(("changes", "loc", "msg"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_pins_are_a_4xx_naming_the_field(
    client: TestClient, changes: dict[str, Any], loc: list[Any], msg: str | None
) -> None:
    for solver in ("optimal", "greedy"):
        r = client.post("/allocate", json=body(solver=solver, **changes))
        assert r.status_code == 422, r.text[:1000]
        assert_names(assert_error_shape(r.json()), loc, msg)
