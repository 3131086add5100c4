"""Living plans with teams (docs/living-plans.md#teams-in-a-revision) through the API, on real
SQLite: a revision after a member becomes unavailable re-forms the teams it must (members valid,
eligible, distinct, the cap kept) while pins keep whole teams; a team that can no longer be formed
is a 422 naming the task and feature with nothing written; the diff names the members that left
and joined; the trace still verifies online and offline."""

from __future__ import annotations

import math
from pathlib import Path
from typing import Any

from fastapi.testclient import TestClient

from app.cli.revise import held_by
from tests.api.test_api_bad_requests import assert_error_shape
from tests.audit.test_docs_check_trace import check_trace_source
from tests.plans.test_revisions import revise, wait_status
from tests.support.offline_check import check_offline

ROBOTS: list[dict[str, Any]] = [
    {"name": "crane", "success": {"heavy": 0.9, "careful": 0.2}, "skills": ["heavy"]},
    {"name": "lifter", "success": {"heavy": 0.8, "careful": 0.4}},
    {"name": "hoist", "success": {"heavy": 0.7, "careful": 0.5}},
    {"name": "arm", "success": {"heavy": 0.3, "careful": 0.95}, "skills": ["careful"]},
    {"name": "hand", "success": {"heavy": 0.2, "careful": 0.85}, "skills": ["careful"]},
]
TASKS: list[dict[str, Any]] = [
    {"id": "beam", "name": "Lift beam", "team": {"heavy": 2}},
    {"id": "panel", "name": "Fix panel", "team": {"heavy": 1, "careful": 1}},
    {"id": "truss", "name": "Raise truss", "team": {"heavy": 3}},
    {"id": "glaze", "name": "Glaze", "team": {"careful": 2}},
    {"id": "sweep", "name": "Sweep", "features": ["careful"]},
    {"id": "carry", "name": "Carry", "features": ["heavy"]},
    {"id": "seal", "name": "Seal joint", "team": {"careful": 1, "heavy": 1}},
]
BODY: dict[str, Any] = {"tasks": TASKS, "robots": ROBOTS, "reasoner": "rules", "mode": "balanced"}
SKILLS = {r["name"]: set(r.get("skills") or r["success"]) for r in ROBOTS}


def completed(client: TestClient) -> dict[str, Any]:
    created = client.post("/runs", json=BODY)
    assert created.status_code == 202, created.text
    return wait_status(client, created.json()["id"], "completed")


def members(a: dict[str, Any]) -> list[str]:
    return [m["robot"] for m in a["team"]] if a.get("team") else [a["robot"]]


def check_plan(run: dict[str, Any], tasks: list[dict[str, Any]], off: set[str]) -> None:
    """Every team task covered unit by unit by distinct robots that may cover each unit, no
    unpinned task on an unavailable robot, and the loads of the available robots in the cap."""
    by_id = {str(a["task_id"]): a for a in run["assignments"]}
    loads = {r["name"]: 0 for r in ROBOTS if r["name"] not in off}
    for task in tasks:
        a = by_id[task["id"]]
        if "team" in task:
            units = [f for f, c in task["team"].items() for _ in range(c)]
            assert [m["feature"] for m in a["team"]] == units, a
            for m in a["team"]:
                assert m["feature"] in SKILLS[m["robot"]], m
        else:
            assert a.get("team") is None and set(task["features"]) <= SKILLS[a["robot"]]
        robots = members(a)
        assert len(set(robots)) == len(robots) and robots[0] == a["robot"], a
        if not a["pinned"]:
            assert not off & set(robots), a
        for r in robots:
            if r not in off:
                loads[r] += 1
    w = sum(loads.values()) / len(loads)
    c = run["max_deviation"]
    lo, hi = max(0, math.ceil(w - c - 1e-9)), math.floor(w + c + 1e-9)
    assert all(lo <= x <= hi for x in loads.values()), (loads, lo, hi)


def verified(client: TestClient, run_id: str, tmp_path: Path) -> None:
    report = client.get(f"/runs/{run_id}/trace/verify").json()
    assert report["ok"] is True, report
    export = tmp_path / f"{run_id}.jsonl"
    export.write_text(client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text)
    script = tmp_path / "check_trace.py"
    script.write_text(check_trace_source())
    checked = check_offline(export, script=script)
    assert checked.returncode == 0, checked.stdout + checked.stderr


def test_a_member_unavailable_re_forms_its_team_and_pins_keep_whole_teams(
    client: TestClient, tmp_path: Path
) -> None:
    parent = completed(client)
    check_plan(parent, TASKS, set())
    by_id = {str(a["task_id"]): a for a in parent["assignments"]}
    beam, panel = members(by_id["beam"]), members(by_id["panel"])
    # A member of the started panel team who is not in the done beam team becomes unavailable.
    gone = next(r for r in panel if r not in beam)
    sent = client.post(
        f"/runs/{parent['id']}/execution",
        json={
            "updates": [
                {"task_id": "beam", "state": "started"},
                {"task_id": "beam", "state": "done"},
                {"task_id": "panel", "state": "started"},
            ]
        },
    )
    assert sent.status_code == 200, sent.text
    created = revise(
        client,
        parent["id"],
        {"changes": [{"type": "robot_unavailable", "robot": gone}], "reason": "hydraulics"},
    )
    revision = wait_status(client, created["id"], "completed")
    now = {str(a["task_id"]): a for a in revision["assignments"]}
    # The done team task keeps its whole team, members and success as decided.
    assert now["beam"]["pinned"] and now["beam"]["team"] == by_id["beam"]["team"]
    assert now["beam"]["success"] == by_id["beam"]["success"]
    # The started team lost a member: not pinned, re-formed without it.
    assert not now["panel"]["pinned"] and gone not in members(now["panel"])
    check_plan(revision, TASKS, {gone})

    diff = client.get(f"/runs/{created['id']}/diff").json()
    moved = {str(c["task_id"]): c for c in diff["robot_changes"]}
    assert gone in moved["panel"]["members_left"]
    assert moved["panel"]["from_team"] == by_id["panel"]["team"]
    assert moved["panel"]["to_team"] == now["panel"]["team"]
    assert moved["panel"]["members_joined"] == [r for r in members(now["panel"]) if r not in panel]
    assert "beam" not in moved
    # The console's diff and `ltaa revise` show every member, before and after.
    fragment = client.get(f"/console/runs/{created['id']}/diff", params={"fragment": 1}).text
    row = fragment[fragment.index('data-task="panel"') :].split("</tr>")[0]
    assert " + ".join(panel) in row and " + ".join(members(now["panel"])) in row
    assert held_by(moved["panel"], "from") == " + ".join(panel)
    # Every team task that held the robot was re-formed without it.
    for task_id, a in by_id.items():
        if gone in members(a) and task_id != "beam":
            assert task_id in moved and gone in moved[task_id]["members_left"]
    # A revision of the revision pins its teams whole too (its pins' rows carry the team).
    again = revise(client, created["id"], {"changes": [], "pin": "decided", "reason": "hold"})
    kept = wait_status(client, again["id"], "completed")
    assert [(a["pinned"], a.get("team")) for a in kept["assignments"]] == [
        (True, a.get("team")) for a in revision["assignments"]
    ]
    for run_id in (parent["id"], created["id"], again["id"]):
        verified(client, run_id, tmp_path)


def test_a_pinned_team_keeps_an_unavailable_member_and_counts_only_the_available(
    client: TestClient,
) -> None:
    parent = completed(client)
    beam, truss = members(parent["assignments"][0]), members(parent["assignments"][2])
    # Committed: the beam and the truss (which needs every heavy robot) keep their crews, though
    # one of the beam's members is then taken off the site.
    created = revise(
        client,
        parent["id"],
        {
            "changes": [{"type": "robot_unavailable", "robot": beam[1]}],
            "pin": {"task_ids": ["beam", "truss"]},
            "reason": "committed crews",
        },
    )
    revision = wait_status(client, created["id"], "completed")
    first, third = revision["assignments"][0], revision["assignments"][2]
    assert first["pinned"] and members(first) == beam
    assert third["pinned"] and members(third) == truss
    check_plan(revision, TASKS, {beam[1]})
    # Loads count the pins' available members only: the unavailable one carries nothing new.
    assert revision["workload"][beam[1]] == 2


def test_a_team_that_can_no_longer_be_formed_is_a_422_and_nothing_is_written(
    client: TestClient,
) -> None:
    parent = completed(client)
    before = client.get("/runs").json()
    # Three robots cover `heavy` (crane, lifter, hoist): the truss needs all three at once.
    r = client.post(
        f"/runs/{parent['id']}/revisions",
        json={"changes": [{"type": "robot_unavailable", "robot": "hoist"}], "reason": "x"},
    )
    assert r.status_code == 422, r.text
    (item,) = assert_error_shape(r.json())
    assert item["loc"][-1] == "changes"
    assert "'truss'" in item["msg"] and "'heavy'" in item["msg"] and "only 2" in item["msg"]
    assert client.get("/runs").json() == before
    after = client.get(f"/runs/{parent['id']}").json()
    assert after["superseded_by"] is None and after["status"] == "completed"
    assert client.get(f"/runs/{parent['id']}/revisions").json()[-1]["id"] == parent["id"]


def test_an_added_team_task_is_planned_with_a_team(client: TestClient, tmp_path: Path) -> None:
    parent = completed(client)
    added = {"id": "mast", "name": "Stand mast", "team": {"heavy": 1, "careful": 1}}
    created = revise(
        client,
        parent["id"],
        {
            "changes": [{"type": "add_tasks", "tasks": [added]}],
            "pin": "decided",
            "reason": "new mast",
        },
    )
    revision = wait_status(client, created["id"], "completed")
    check_plan(revision, [*TASKS, {**added}], set())
    last = revision["assignments"][-1]
    assert last["task_id"] == "mast" and [m["feature"] for m in last["team"]] == [
        "heavy",
        "careful",
    ]
    # Every parent decision is pinned with its whole team.
    for was, now in zip(parent["assignments"], revision["assignments"][:-1], strict=True):
        assert now["pinned"] and now.get("team") == was.get("team")
    verified(client, created["id"], tmp_path)


def test_a_team_task_added_to_a_timed_run_is_formed_in_time(client: TestClient) -> None:
    """Once refused: the graph now forms teams in time (docs/living-plans.md#teams-in-a-revision),
    so the added team task gets distinct members that may cover its units, and one start and
    end that every member's lane holds."""
    tasks = [
        {"id": "pour", "features": ["heavy"], "duration": 30},
        {"id": "trim", "features": ["careful"], "duration": 20},
    ]
    created = client.post("/runs", json={**BODY, "tasks": tasks})
    assert created.status_code == 202, created.text
    parent = wait_status(client, created.json()["id"], "completed")
    added = {"id": "mast", "team": {"heavy": 2}, "duration": 15, "after": ["pour"]}
    revision = revise(
        client,
        parent["id"],
        {"changes": [{"type": "add_tasks", "tasks": [added]}], "reason": "mast"},
    )
    state = wait_status(client, revision["id"], "completed")
    by_id = {str(a["task_id"]): a for a in state["assignments"]}
    mast = by_id["mast"]
    crew = members(mast)
    assert [m["feature"] for m in mast["team"]] == ["heavy", "heavy"] and len(set(crew)) == 2
    assert all("heavy" in SKILLS[name] for name in crew)
    assert mast["start"] >= by_id["pour"]["end"] and abs(mast["end"] - mast["start"] - 15) < 1e-6
    lanes = client.get(f"/runs/{revision['id']}/schedule").json()["robots"]
    for name in crew:
        worked = [
            i for i in lanes[name]["lane"] if i.get("task_id") == "mast" and i["kind"] == "task"
        ]
        assert [(i["start"], i["end"]) for i in worked] == [(mast["start"], mast["end"])]


def test_a_pinned_team_survives_a_member_re_rated_to_zero(client: TestClient) -> None:
    parent = completed(client)
    beam = parent["assignments"][0]
    # A member without skills covers what it rates above 0: re-rated to 0 it covers no more
    # `heavy`, but the committed beam keeps its crew and recorded success. (The truss, which
    # needs every heavy robot, is dropped: the instance itself could not staff it any more.)
    member = next(r for r in members(beam) if r in ("lifter", "hoist"))
    created = revise(
        client,
        parent["id"],
        {
            "changes": [
                {"type": "set_rates", "robot": member, "success": {"heavy": 0.0}},
                {"type": "remove_tasks", "task_ids": ["truss"]},
            ],
            "pin": {"task_ids": ["beam"]},
            "reason": "re-rated",
        },
    )
    revision = wait_status(client, created["id"], "completed")
    now = revision["assignments"]
    assert now[0]["pinned"] and (now[0]["team"], now[0]["success"]) == (
        beam["team"],
        beam["success"],
    )
    for a in now:
        if not a["pinned"] and a.get("team"):
            assert {"robot": member, "feature": "heavy"} not in a["team"], a
