"""Timed team revisions (docs/living-plans.md#teams-in-a-revision) through the API, on real
SQLite: a team task the site reported is pinned whole, at its reported times, while a member
becoming unavailable re-forms a later team in time (it waits for the reported end and for
`now`); a team task added to a timed run is planned as a team in time; the revision's schedule
puts each team in every member's lane, and the trace verifies."""

from __future__ import annotations

import copy
from datetime import datetime, timedelta
from typing import Any

from fastapi.testclient import TestClient

from tests.plans.test_revisions import revise, wait_status

START = "2026-12-07T07:00:00+01:00"
ROBOTS: list[dict[str, Any]] = [
    {
        "name": "crane",
        "success": {"heavy": 0.9, "careful": 0.2},
        "skills": ["heavy"],
        "zone": "north",
    },
    {"name": "lifter", "success": {"heavy": 0.8, "careful": 0.4}, "zone": "north"},
    {
        "name": "arm",
        "success": {"heavy": 0.3, "careful": 0.95},
        "skills": ["careful"],
        "zone": "south",
    },
    {
        "name": "hand",
        "success": {"heavy": 0.2, "careful": 0.85},
        "skills": ["careful"],
        "zone": "south",
    },
    {"name": "rigger", "success": {"heavy": 0.7, "careful": 0.6}, "zone": "south"},
]
TASKS: list[dict[str, Any]] = [
    {"id": "beam", "name": "Lift beam", "team": {"heavy": 2}, "duration": 30, "zone": "north"},
    {
        "id": "panel",
        "name": "Fix panel",
        "team": {"heavy": 1, "careful": 1},
        "duration": 20,
        "zone": "south",
        "after": ["beam"],
    },
    {"id": "sweep", "name": "Sweep", "features": ["careful"], "duration": 15, "zone": "south"},
    {"id": "carry", "name": "Carry", "features": ["heavy"], "duration": 10, "zone": "north"},
    {"id": "seal", "name": "Seal", "team": {"careful": 2}, "duration": 10, "zone": "south"},
]
BODY: dict[str, Any] = {
    "tasks": TASKS,
    "robots": ROBOTS,
    "travel": {"north": {"south": 6}},
    "start": START,
    "reasoner": "rules",
    "mode": "balanced",
}


def at(minute: float) -> str:
    return (datetime.fromisoformat(START) + timedelta(minutes=minute)).isoformat()


def members(a: dict[str, Any]) -> list[str]:
    return [m["robot"] for m in a["team"]] if a.get("team") else [a["robot"]]


def completed(client: TestClient, body: dict[str, Any] = BODY) -> dict[str, Any]:
    created = client.post("/runs", json=copy.deepcopy(body))
    assert created.status_code == 202, created.text
    return wait_status(client, created.json()["id"], "completed")


def lanes_hold_teams(client: TestClient, run_id: str, run: dict[str, Any]) -> None:
    schedule = client.get(f"/runs/{run_id}/schedule").json()
    for a in run["assignments"]:
        for name in members(a):
            lane = schedule["robots"][name]["lane"]
            worked = [
                (i["start"], i["end"])
                for i in lane
                if i["kind"] == "task" and i["task_id"] == a["task_id"]
            ]
            assert worked == [(a["start"], a["end"])], (a["task_id"], name, lane)
    assert client.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True


def test_a_reported_team_is_pinned_whole_and_an_unavailable_member_re_forms_a_team_in_time(
    client: TestClient,
) -> None:
    parent = completed(client)
    by_id = {a["task_id"]: a for a in parent["assignments"]}
    beam, panel = by_id["beam"], by_id["panel"]
    lanes_hold_teams(client, parent["id"], parent)
    # The beam ran 10 minutes late; a member of the panel's team leaves before it starts.
    late_end = beam["end"] + 10
    updates = [
        {"task_id": "beam", "state": "started", "at": at(beam["start"])},
        {"task_id": "beam", "state": "done", "at": at(late_end)},
    ]
    assert client.post(f"/runs/{parent['id']}/execution", json={"updates": updates}).is_success
    # The current schedule (docs/living-plans.md#the-runs-current-schedule): the late beam in
    # both members' lanes, and the panel after it in each of its members'.
    current = client.get(f"/runs/{parent['id']}/schedule").json()["robots"]

    def worked(name: str, task_id: str) -> list[tuple[float, float]]:
        lane = current[name]["lane"]
        return [
            (i["start"], i["end"])
            for i in lane
            if i.get("task_id") == task_id and i["kind"] == "task"
        ]

    assert all(worked(m, "beam") == [(beam["start"], late_end)] for m in members(beam))
    panel_times = {worked(m, "panel")[0] for m in members(panel)}
    assert len(panel_times) == 1 and min(panel_times)[0] >= late_end
    gone = next(m for m in members(panel) if m not in members(beam))
    now = late_end + 1
    created = revise(
        client,
        parent["id"],
        {
            "now": at(now),
            "changes": [{"type": "robot_unavailable", "robot": gone}],
            "reason": f"{gone} is called away",
        },
    )
    revision = wait_status(client, created["id"], "completed")
    after = {a["task_id"]: a for a in revision["assignments"]}
    kept = after["beam"]
    assert kept["pinned"] and kept["team"] == beam["team"]  # the whole team, as reported
    assert (kept["start"], kept["end"]) == (beam["start"], late_end)
    reformed = after["panel"]
    assert gone not in members(reformed)
    assert [m["feature"] for m in reformed["team"]] == ["heavy", "careful"]
    assert len(set(members(reformed))) == 2
    assert reformed["start"] >= max(late_end, now)  # after the beam's real end, and `now`
    for task_id, a in after.items():
        if not a["pinned"]:
            assert gone not in members(a), task_id
            assert a["start"] >= now, task_id
    lanes_hold_teams(client, created["id"], revision)
    # The diff names who left the panel's team and shows the schedule's moves in time.
    diff = client.get(f"/runs/{created['id']}/diff").json()
    (change,) = [c for c in diff["robot_changes"] if c["task_id"] == "panel"]
    assert gone in change["members_left"] and change["members_joined"]
    moved = {m["task_id"]: m for m in diff["schedule"]["moves"]}
    # The beam was at its reported times in the parent's current schedule already: no move.
    assert "beam" not in moved and moved["panel"]["start_after"] == reformed["start"]


def test_a_team_task_added_to_a_timed_run_is_planned_as_a_team_in_time(
    client: TestClient,
) -> None:
    parent = completed(client)
    added = {"id": "mast", "name": "Raise mast", "team": {"heavy": 2}, "duration": 15}
    added |= {"zone": "north", "after": ["carry"]}
    created = revise(
        client,
        parent["id"],
        {"now": at(0), "changes": [{"type": "add_tasks", "tasks": [added]}], "reason": "mast"},
    )
    revision = wait_status(client, created["id"], "completed")
    after = {a["task_id"]: a for a in revision["assignments"]}
    mast = after["mast"]
    assert [m["feature"] for m in mast["team"]] == ["heavy", "heavy"]
    assert len(set(members(mast))) == 2
    assert mast["start"] >= after["carry"]["end"]
    lanes_hold_teams(client, created["id"], revision)
