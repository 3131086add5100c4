"""Pins on team tasks in POST /allocate (docs/living-plans.md#pins-in-allocate): a pin carries the
whole team, `{"task_id", "team": [{"robot", "feature"}, ...]}` (`robot` optional: the member
covering the first unit, as answers read); every method that forms teams keeps it, timed and
untimed, the exact ones at the optimum given the pins (tests/domain/test_team_pins_exhaustive.py
checks that against an exhaustive search); a bad pin is a 422 naming the field."""

from __future__ import annotations

import copy
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.solvers.base import TEAM_METHODS
from tests.allocation.test_api_teams import TEAM_BODY
from tests.api.test_api_bad_requests import assert_error_shape, assert_names

# The panel (one heavy, one careful) pinned on the arm (careful) and the lifter (heavy), given
# in another order than the units': the answer lists them in unit order.
PANEL_PIN = {
    "task_id": "panel",
    "team": [{"robot": "arm", "feature": "careful"}, {"robot": "lifter", "feature": "heavy"}],
}
PANEL_TEAM = [{"robot": "lifter", "feature": "heavy"}, {"robot": "arm", "feature": "careful"}]


def body(**changes: Any) -> dict[str, Any]:
    out = copy.deepcopy(TEAM_BODY)
    out.update({"solver": "optimal", "mode": "balanced", **changes})
    return out


def members(assignment: dict[str, Any]) -> list[str]:
    return [m["robot"] for m in assignment.get("team") or [{"robot": assignment["robot"]}]]


@pytest.mark.parametrize("solver", TEAM_METHODS)
def test_every_team_method_keeps_a_pinned_team(client: TestClient, solver: str) -> None:
    r = client.post("/allocate", json=body(solver=solver, pinned=[PANEL_PIN]))
    assert r.status_code == 200, r.text
    data = r.json()
    rows = {a["task_id"]: a for a in data["assignments"]}
    panel = rows["panel"]
    assert panel["pinned"] is True and panel["team"] == PANEL_TEAM
    assert panel["robot"] == "lifter"  # the first unit's member, as every team answer reads
    assert not any(a.get("pinned") for a in data["assignments"] if a["task_id"] != "panel")
    loads = {"crane": 0, "arm": 0, "lifter": 0}
    for a in data["assignments"]:
        for name in members(a):
            loads[name] += 1
    assert data["metrics"]["workload"] == loads
    assert all(1 <= x <= 3 for x in loads.values()), loads  # W = 2, the balanced cap 1


@pytest.mark.parametrize("solver", TEAM_METHODS)
def test_a_pinned_team_keeps_a_member_that_is_unavailable(client: TestClient, solver: str) -> None:
    """The arm covers the pinned panel's careful unit and is off the site: the pin stays whole,
    the arm takes no new task, and the balance is over the crane and the lifter."""
    request = body(solver=solver, mode="success_focused", pinned=[PANEL_PIN], unavailable=["arm"])
    r = client.post("/allocate", json=request)
    assert r.status_code == 200, r.text
    rows = {a["task_id"]: a for a in r.json()["assignments"]}
    assert rows["panel"]["team"] == PANEL_TEAM and rows["panel"]["pinned"] is True
    assert all("arm" not in members(a) for tid, a in rows.items() if tid != "panel")


def test_the_exact_methods_agree_given_a_pinned_team(client: TestClient) -> None:
    es = {}
    for solver in ("optimal", "dp", "brute_force", "schedule"):
        r = client.post(
            "/allocate", json=body(solver=solver, mode="success_focused", pinned=[PANEL_PIN])
        )
        assert r.status_code == 200, r.text
        es[solver] = r.json()["metrics"]["expected_success"]
    # The beam on crane + lifter (0.85), the panel as pinned (0.875), the sweep on the arm
    # (0.95), the carry on the crane (0.9): the lifter carries two units, within the mode's cap.
    assert es["optimal"] == pytest.approx((0.85 + 0.875 + 0.95 + 0.9) / 4)
    assert all(v == pytest.approx(es["optimal"], abs=1e-12) for v in es.values()), es


def test_a_consistent_robot_is_accepted_beside_the_team(client: TestClient) -> None:
    pin = {**PANEL_PIN, "robot": "lifter"}
    r = client.post("/allocate", json=body(pinned=[pin]))
    assert r.status_code == 200, r.text
    assert {a["task_id"]: a for a in r.json()["assignments"]}["panel"]["team"] == PANEL_TEAM


@pytest.mark.parametrize("solver", ["optimal", "dp", "greedy", "schedule", "ltaa"])
def test_a_timed_team_pin_with_a_start_holds_every_members_lane(
    client: TestClient, solver: str
) -> None:
    plain = client.post("/allocate", json={"solver": "optimal", "scenario": "baseline_team"})
    assert plain.status_code == 200, plain.text
    first = next(a for a in plain.json()["assignments"] if a.get("team"))
    taken = {m["robot"] for m in first["team"]}
    # Another valid team than the optimum's: its second unit on the robot left out of it.
    other = next(name for name in ("light", "medium", "heavy") if name not in taken)
    team = [first["team"][0], {"robot": other, "feature": first["team"][1]["feature"]}]
    pin = {"task_id": first["task_id"], "team": team, "start": 30}
    options = {"time_limit_s": 5} if solver == "schedule" else {}
    r = client.post(
        "/allocate",
        json={"solver": solver, "scenario": "baseline_team", "pinned": [pin], "options": options},
    )
    assert r.status_code == 200, r.text
    data = r.json()
    assert data["schedule_violations"] == []
    row = next(a for a in data["assignments"] if a["task_id"] == first["task_id"])
    assert row["pinned"] is True and row["team"] == team and row["start"] == 30
    lanes = data["schedule"]["robots"]
    for m in team:  # in every member's lane, over the same times
        lane = lanes[m["robot"]]["lane"]
        worked = [i for i in lane if i["kind"] == "task" and i["task_id"] == first["task_id"]]
        assert [(i["start"], i["end"]) for i in worked] == [(30, row["end"])], lane
    if solver not in ("greedy", "ltaa"):  # the exact optimum given the pin: dp, schedule
        exact = client.post(
            "/allocate",
            json={"solver": "optimal", "scenario": "baseline_team", "pinned": [pin]},
        ).json()["metrics"]["expected_success"]
        assert data["metrics"]["expected_success"] == pytest.approx(exact, abs=1e-12)


BAD: list[tuple[str, dict[str, Any], list[Any], str]] = [
    (
        "team_task_pinned_on_a_robot",
        {"task_id": "beam", "robot": "crane"},
        ["pinned", 0, "team"],
        "whole team",
    ),
    (
        "team_on_a_one_robot_task",
        {"task_id": "sweep", "team": [{"robot": "arm", "feature": "careful"}]},
        ["pinned", 0, "team"],
        "one-robot task",
    ),
    (
        "unknown_feature",
        {"task_id": "beam", "team": [{"robot": "crane", "feature": "welding"}]},
        ["pinned", 0, "team", 0, "feature"],
        "'welding'",
    ),
    (
        "unknown_robot",
        {
            "task_id": "beam",
            "team": [{"robot": "crane", "feature": "heavy"}, {"robot": "x", "feature": "heavy"}],
        },
        ["pinned", 0, "team", 1, "robot"],
        "unknown robot 'x'",
    ),
    (
        "a_robot_twice",
        {
            "task_id": "beam",
            "team": [
                {"robot": "crane", "feature": "heavy"},
                {"robot": "crane", "feature": "heavy"},
            ],
        },
        ["pinned", 0, "team", 1, "robot"],
        "distinct",
    ),
    (
        "a_robot_that_cannot_cover",
        {
            "task_id": "panel",
            "team": [
                {"robot": "arm", "feature": "heavy"},
                {"robot": "crane", "feature": "careful"},
            ],
        },
        ["pinned", 0, "team", 1, "robot"],
        "not in its skills",
    ),
    (
        "a_unit_left_uncovered",
        {"task_id": "beam", "team": [{"robot": "crane", "feature": "heavy"}]},
        ["pinned", 0, "team"],
        "needs 2 robot(s) for 'heavy'",
    ),
    (
        "robot_not_the_first_units_member",
        {**PANEL_PIN, "robot": "arm"},
        ["pinned", 0, "robot"],
        "first unit",
    ),
    ("neither_robot_nor_team", {"task_id": "sweep"}, ["pinned", 0, "robot"], "give the robot"),
    ("empty_team", {"task_id": "beam", "team": []}, ["pinned", 0, "team"], ""),
    (
        "member_extra_key",
        {"task_id": "beam", "team": [{"robot": "crane", "feature": "heavy", "at": 1}]},
        ["pinned", 0, "team", 0, "at"],
        "",
    ),
]


@pytest.mark.parametrize(("pin", "loc", "words"), [c[1:] for c in BAD], ids=[c[0] for c in BAD])
def test_bad_team_pins_are_a_422_naming_the_field(
    client: TestClient, pin: dict[str, Any], loc: list[Any], words: str
) -> None:
    for solver in ("optimal", "greedy"):
        r = client.post("/allocate", json=body(solver=solver, pinned=[pin]))
        assert r.status_code == 422, r.text[:1000]
        assert_names(assert_error_shape(r.json()), ["body", *loc], words or None)


@pytest.mark.parametrize("solver", TEAM_METHODS)
def test_every_team_method_answers_when_every_task_is_pinned(
    client: TestClient, solver: str
) -> None:
    """Nothing left to decide (both team tasks pinned with their teams, the rest on robots):
    every method answers the pins as they stand, the graph with no decision of its own."""
    pins = [
        PANEL_PIN,
        {
            "task_id": "beam",
            "team": [
                {"robot": "lifter", "feature": "heavy"},
                {"robot": "crane", "feature": "heavy"},
            ],
        },
        {"task_id": "sweep", "robot": "arm"},
        {"task_id": "carry", "robot": "lifter"},
    ]
    r = client.post("/allocate", json=body(solver=solver, pinned=pins))
    assert r.status_code == 200, r.text
    rows = {a["task_id"]: a for a in r.json()["assignments"]}
    assert all(a["pinned"] is True for a in rows.values())
    assert rows["panel"]["team"] == PANEL_TEAM and members(rows["beam"]) == ["lifter", "crane"]
