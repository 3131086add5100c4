"""POST /allocate on a timed instance with team tasks (docs/allocation.md#teams,
docs/schedules.md#teams-in-time): every team method answers valid teams with a feasible
schedule that shows each team task in every member's lane (the LTAA graph on its own
time lines, each team decision recording its members' start and end); the methods that
cannot form teams in time refuse with a sentence naming the field and the methods to use."""

from __future__ import annotations

import copy
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.solvers.registry import solver_names
from tests.allocation.test_api_teams import TEAM_BODY
from tests.api.test_api_bad_requests import assert_error_shape
from tests.solvers.test_solver_conformance import FAST_OPTIONS

ZONES = {"beam": "north", "panel": "south", "sweep": "south", "carry": "north"}
TIMED_TEAM_BODY: dict[str, Any] = {
    "tasks": [
        {**task, "duration": minutes, "zone": ZONES[task["id"]]}
        for task, minutes in zip(TEAM_BODY["tasks"], (30, 20, 15, 10), strict=True)
    ],
    "robots": [
        {**robot, "zone": zone}
        for robot, zone in zip(TEAM_BODY["robots"], ("north", "south", "north"), strict=True)
    ],
    "travel": {"north": {"south": 6}},
    "start": "2026-12-07T07:00:00+01:00",
}
TIMED_TEAM_BODY["tasks"][1]["after"] = ["beam"]  # the panel is fixed once the beam is up

# The methods that form teams and get a schedule (the list scheduler, CP-SAT's own, or the
# LTAA graph's time lines).
SCHEDULED = {"optimal", "dp", "brute_force", "greedy", "schedule", "ltaa"}


@pytest.mark.parametrize("solver", solver_names())
def test_every_method_schedules_valid_teams_or_refuses(client: TestClient, solver: str) -> None:
    request = {
        **copy.deepcopy(TIMED_TEAM_BODY),
        "solver": solver,
        "mode": "balanced",
        "seed": 1,
        "options": FAST_OPTIONS.get(solver, {}),
    }
    r = client.post("/allocate", json=request)
    if solver not in SCHEDULED:
        assert r.status_code == 422, r.text
        (item,) = assert_error_shape(r.json())
        assert item["loc"] == ["body", "tasks", 0, "team"]
        assert f"'{solver}'" in item["msg"] and "'schedule'" in item["msg"], item["msg"]
        return
    assert r.status_code == 200, r.text
    data = r.json()
    assert data["schedule_violations"] == []
    schedule = data["schedule"]
    by_task = {entry["task_id"]: entry for entry in schedule["tasks"]}
    for task, a in zip(TIMED_TEAM_BODY["tasks"], data["assignments"], strict=True):
        entry = by_task[task["id"]]
        assert (a["start"], a["end"]) == (entry["start"], entry["end"])
        if "team" not in task:
            assert "team" not in a and "team" not in entry
            continue
        units = [f for f, c in task["team"].items() for _ in range(c)]
        members = [m["robot"] for m in a["team"]]
        assert [m["feature"] for m in a["team"]] == units and len(set(members)) == len(units)
        assert a["robot"] == members[0]
        assert [m["robot"] for m in entry["team"]] == members
        for name in members:  # the task in every member's lane, over the same times
            lane = schedule["robots"][name]["lane"]
            worked = [i for i in lane if i["kind"] == "task" and i["task_id"] == task["id"]]
            assert [(i["start"], i["end"]) for i in worked] == [(a["start"], a["end"])]
    panel, beam = by_task["panel"], by_task["beam"]
    assert panel["start"] >= beam["end"]  # precedence holds for the whole team
    if solver == "schedule":
        assert data["status"] == "optimal" and "multi-skill" in data["model"]


def test_ltaa_forms_teams_in_time_on_its_own_time_lines(client: TestClient) -> None:
    """docs/allocation.md#teams: the graph decides in time order and a team starts when its
    last member can begin: the beam's members both start north, and the panel (after the
    beam) waits for the beam's member that must travel to the south."""
    request = {**copy.deepcopy(TIMED_TEAM_BODY), "solver": "ltaa"}
    r = client.post("/allocate", json=request)
    assert r.status_code == 200, r.text
    data = r.json()
    assert data["schedule_violations"] == [] and data["schedule_model"].startswith("the LTAA")
    by_id = {a["task_id"]: a for a in data["assignments"]}
    zones = {robot["name"]: robot["zone"] for robot in TIMED_TEAM_BODY["robots"]}
    beam, panel = by_id["beam"], by_id["panel"]
    beam_team = [m["robot"] for m in beam["team"]]
    assert beam["start"] == max(0 if zones[n] == "north" else 6 for n in beam_team)
    arrivals = []
    for m in panel["team"]:
        name = m["robot"]
        if name in beam_team:  # busy on the beam in the north, then 6 minutes south
            arrivals.append(beam["end"] + 6)
        else:
            earlier = [a for a in data["assignments"] if a["robot"] == name and "team" not in a]
            free = max((a["end"] for a in earlier if a["end"] <= panel["start"]), default=0)
            arrivals.append(free + (0 if zones[name] == "south" else 6))
    assert panel["start"] == max(arrivals)


def test_baseline_team_is_listed_and_planned_by_every_team_method(client: TestClient) -> None:
    """docs/schedules.md#the-team-scenario: GET /scenarios lists it with `team: true`; sent
    back as its own tasks it is the same instance; every team method plans it."""
    listed = {s["name"]: s for s in client.get("/scenarios").json()}
    team = listed["baseline_team"]
    assert team["timed"] is True and team["team"] is True
    assert listed["baseline_timed"]["team"] is False
    teams = {t["id"]: t["team"] for t in team["tasks"] if t.get("team")}
    assert teams == {
        200: {"heavy": 2},
        201: {"heavy": 2},
        203: {"heavy": 2},
        3: {"heavy": 1, "careful": 1},
        11: {"heavy": 1, "careful": 1},
        13: {"heavy": 1, "careful": 1},
        210: {"heavy": 1, "careful": 1},
    }
    assert all(isinstance(t["duration"], float | int) for t in team["tasks"] if t.get("team"))
    own = {k: team[k] for k in ("tasks", "robots", "travel", "start")}
    for solver in sorted(SCHEDULED):
        options = {"time_limit_s": 1} if solver == "schedule" else {}
        by_name = client.post(
            "/allocate", json={"scenario": "baseline_team", "solver": solver, "options": options}
        )
        if solver == "brute_force":  # 36 tasks: past its limit, and it says so
            assert by_name.status_code == 422 and "too_large" in by_name.text
            continue
        assert by_name.status_code == 200, by_name.text
        data = by_name.json()
        assert data["schedule_violations"] == [], (solver, data["schedule_violations"])
        assert sum(len(a.get("team") or [a]) for a in data["assignments"]) == 43  # units
        if solver == "optimal":
            by_content = client.post("/allocate", json={**own, "solver": solver})
            assert by_content.status_code == 200, by_content.text
            for key in ("assignments", "metrics", "schedule"):
                assert by_content.json()[key] == data[key]
