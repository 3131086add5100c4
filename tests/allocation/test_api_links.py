"""Typed links with lags through the API (docs/schedules.md#links): every solver of
POST /allocate plans them feasibly, `schedule` finds the exhaustive optimum, bad links are
a 422 naming the field, a durable run over an MPXJ-written draft plans them, and a late
predecessor moves its SS and FF successors as each link says, in the run's schedule and in a
revision."""

from __future__ import annotations

import copy
from datetime import datetime, timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.exchange import read_mspdi, read_xer
from tests.plans.test_revisions import completed_run, wait_status
from tests.support.timed_checks import best_makespan, feasibility_errors

START = "2026-03-02T07:00:00+00:00"
ROBOTS: list[dict[str, Any]] = [
    {"name": "pump", "success": {"pour": 0.9, "screed": 0.3, "lift": 0.2}},
    {"name": "screeder", "success": {"pour": 0.2, "screed": 0.9, "lift": 0.3}},
    {"name": "crane", "success": {"pour": 0.3, "screed": 0.2, "lift": 0.9}},
]
TASKS: list[dict[str, Any]] = [
    {"id": "pour", "features": ["pour"], "duration": 40},
    {"id": "screed", "features": ["screed"], "duration": 30,
     "after": [{"task": "pour", "type": "SS", "lag": 20}]},
    {"id": "trowel", "features": ["screed"], "duration": 15,
     "after": [{"task": "screed", "type": "FF", "lag": 10}]},
    {"id": "lift", "features": ["lift"], "duration": {"crane": 25, "pump": 35},
     "after": [{"task": "pour", "type": "FS", "lag": -10}, "screed"]},
    {"id": "strip", "features": ["lift"], "duration": 10,
     "after": [{"task": "trowel", "type": "SF", "lag": 30}]},
]  # fmt: skip


def body(solver: str = "schedule", **changes: Any) -> dict[str, Any]:
    out = {"solver": solver, "mode": "success_focused", "tasks": TASKS, "robots": ROBOTS}
    return copy.deepcopy({**out, "start": START, **changes})


@pytest.mark.parametrize("solver", ["greedy", "optimal", "dp", "brute_force", "schedule"])
def test_every_solver_plans_typed_links_feasibly(client: TestClient, solver: str) -> None:
    sent = body(solver)
    answer = client.post("/allocate", json=sent)
    assert answer.status_code == 200, answer.text
    block = answer.json()["schedule"]
    assert feasibility_errors(sent, block) == []
    assert answer.json().get("schedule_violations", []) == []
    rows = {r["task_id"]: r for r in block["tasks"]}
    assert rows["screed"]["start"] >= rows["pour"]["start"] + 20
    assert rows["trowel"]["end"] >= rows["screed"]["end"] + 10
    assert rows["strip"]["end"] >= rows["trowel"]["start"] + 30


def test_schedule_is_the_exhaustive_optimum_with_typed_links(client: TestClient) -> None:
    sent = body("schedule", objective="makespan")
    answer = client.post("/allocate", json=sent).json()
    success = [[0.0] * len(ROBOTS) for _ in TASKS]
    _, best = best_makespan(sent, success, None, success_first=False)
    assert answer["schedule"]["makespan"] == pytest.approx(best)
    assert answer["status"] == "optimal"
    # The critical path the answer reports runs through links that bind.
    path = answer["schedule"]["critical_path"]
    assert path[-1]["end"] == answer["schedule"]["makespan"]


def with_after(i: int, after: list[Any]) -> list[dict[str, Any]]:
    tasks = copy.deepcopy(TASKS)
    tasks[i]["after"] = after
    return tasks


@pytest.mark.parametrize(
    ("tasks", "loc", "words"),
    [
        (with_after(1, [{"task": "pour", "type": "XS"}]), [1, "after", 0, "type"], "FS, SS"),
        (with_after(1, [{"task": "pour", "lag": "ten"}]), [1, "after", 0, "lag"], "minutes"),
        (with_after(1, [{"task": "pour", "lag": True}]), [1, "after", 0, "lag"], "minutes"),
        (with_after(1, [{"task": "nope", "type": "SS"}]), [1, "after", 0, "task"], "'nope'"),
        (with_after(1, [{"task": "screed", "type": "SS"}]), [1, "after", 0, "task"], "itself"),
        (
            with_after(
                1, [{"task": "pour", "type": "SS"}, {"task": "pour", "type": "SS", "lag": 5}]
            ),
            [1, "after", 1],
            "twice",
        ),
        (with_after(1, [{"task": "pour", "kind": "SS"}]), [1, "after", 0], "unknown key 'kind'"),
        (with_after(1, [{"type": "SS"}]), [1, "after", 0], "'task' is missing"),
        (
            with_after(0, [{"task": "strip", "type": "SS", "lag": -100}]),
            [2, "after"],  # an `after` on the cycle, which the message writes out
            "cycle",
        ),
    ],
)
def test_a_bad_link_is_a_422_naming_the_field(
    client: TestClient, tasks: list[dict[str, Any]], loc: list[Any], words: str
) -> None:
    runs_before = len(client.get("/runs").json())
    for path, sent in (
        ("/allocate", body(tasks=tasks)),
        ("/runs", {"tasks": tasks, "robots": ROBOTS}),
    ):
        answer = client.post(path, json=sent)
        assert answer.status_code == 422, answer.text
        (detail,) = answer.json()["detail"]
        assert detail["loc"] == ["body", "tasks", *loc], detail
        assert words in detail["msg"], detail
    assert len(client.get("/runs").json()) == runs_before


def test_a_cycle_names_its_tasks_types_and_lags(client: TestClient) -> None:
    tasks = with_after(0, [{"task": "trowel", "type": "FF", "lag": -60}])
    (detail,) = client.post("/allocate", json=body(tasks=tasks)).json()["detail"]
    chain = "'screed' (FF +10 min) -> 'trowel' (FF -60 min) -> 'pour' (SS +20 min) -> 'screed'"
    assert chain in detail["msg"]
    assert detail["type"] == "precedence_cycle"


def draft_request(draft: dict[str, Any]) -> dict[str, Any]:
    """The imported draft with rates filled in, its team task (two resources on one feature)
    sent as the team it is (docs/allocation.md#teams)."""
    features = sorted({f for t in draft["tasks"] for f in t["features"]})
    return {
        "tasks": draft["tasks"],
        "robots": [{**r, "success": dict.fromkeys(features, 0.8)} for r in draft["robots"]],
        "start": draft["start"],
    }


@pytest.mark.usefixtures("mpxj")
def test_an_mpxj_draft_with_all_four_types_and_a_lead_plans_feasibly(client: TestClient) -> None:
    from tests.support.exchange_support import files

    mspdi = read_mspdi(files()["mspdi"], features_field="Text1").to_dict()
    xer = read_xer(files()["xer"], features_field="Features").to_dict()
    assert mspdi["tasks"] == xer["tasks"]
    kinds = {(a["type"], a["lag"] < 0) for t in mspdi["tasks"] for a in t["after"]}
    assert {"FS", "SS", "FF", "SF"} <= {k for k, _ in kinds} and ("FF", True) in kinds
    sent = draft_request(mspdi)
    for solver in ("schedule", "greedy"):
        answer = client.post("/allocate", json={**sent, "solver": solver})
        assert answer.status_code == 200, answer.text
        assert feasibility_errors(sent, answer.json()["schedule"]) == []
    created = client.post("/runs", json={**sent, "reasoner": "rules"})
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    wait_status(client, run_id, "completed")
    planned = client.get(f"/runs/{run_id}/schedule").json()
    assert feasibility_errors(sent, planned) == []
    # The durable run planned the file's team task as a team: two robots, one start and end.
    (rebar,) = [t for t in sent["tasks"] if t.get("team")]
    assert rebar["team"] == {"lift": 2}
    row = next(r for r in planned["tasks"] if str(r["task_id"]) == str(rebar["id"]))
    crew = [m["robot"] for m in row["team"]]
    assert [m["feature"] for m in row["team"]] == ["lift", "lift"] and len(set(crew)) == 2
    for name in crew:
        lane = planned["robots"][name]["lane"]
        assert [(i["start"], i["end"]) for i in lane if i.get("task_id") == row["task_id"]
                and i["kind"] == "task"] == [(row["start"], row["end"])]  # fmt: skip


# -- living plans ------------------------------------------------------------------------------

LIVING: list[dict[str, Any]] = [
    {"id": "pour", "features": ["pour"], "duration": 40},
    {"id": "screed", "features": ["screed"], "duration": 30,
     "after": [{"task": "pour", "type": "SS", "lag": 20}]},
    {"id": "trowel", "features": ["lift"], "duration": 15,
     "after": [{"task": "pour", "type": "FF", "lag": 10}]},
]  # fmt: skip


def at(minute: float) -> str:
    return (datetime.fromisoformat(START) + timedelta(minutes=minute)).isoformat()


def rows_of(schedule: dict[str, Any]) -> dict[str, tuple[float, float]]:
    return {str(r["task_id"]): (r["start"], r["end"]) for r in schedule["tasks"]}


def test_a_late_start_and_a_delay_move_ss_and_ff_successors_as_their_links_say(
    client: TestClient,
) -> None:
    run = {"tasks": LIVING, "robots": ROBOTS, "start": START, "reasoner": "rules"}
    parent = completed_run(client, {**run, "mode": "success_focused"})
    planned = rows_of(client.get(f"/runs/{parent}/schedule").json())
    assert planned == {"pour": (0, 40), "screed": (20, 50), "trowel": (35, 50)}
    # The pour started 15 minutes late (reported): both successors move by 15.
    late = {"updates": [{"task_id": "pour", "state": "started", "at": at(15)}]}
    assert client.post(f"/runs/{parent}/execution", json=late).status_code == 200
    now = rows_of(client.get(f"/runs/{parent}/schedule").json())
    assert now == {"pour": (15, 55), "screed": (35, 65), "trowel": (50, 65)}
    # A revision lengthens the pour by 30: start-to-start waits for its start, unmoved;
    # finish-to-finish for its end, 30 later.
    revised = client.post(
        f"/runs/{parent}/revisions",
        json={
            "reason": "the pump is slow",
            "now": at(20),
            "changes": [{"type": "delay", "task_id": "pour", "minutes": 30}],
        },
    )
    assert revised.status_code == 202, revised.text
    revision = revised.json()["id"]
    wait_status(client, revision, "completed")
    after = rows_of(client.get(f"/runs/{revision}/schedule").json())
    assert after["pour"] == (15, 85)
    assert after["screed"][0] == 35  # SS +20 from the pour's (reported) start
    assert after["trowel"][1] == 95  # FF +10 from the pour's new end
    moves = client.get(f"/runs/{revision}/diff").json()["schedule"]["moves"]
    assert {m["task_id"] for m in moves} == {"pour", "trowel"}


def test_a_removed_task_hands_its_links_on_as_a_bridged_milestone(client: TestClient) -> None:
    # pour -SS+20-> screed -FF+10-> trowel; screed removed: trowel's end is at least 30
    # after the pour starts (SF +30), not after anything screed would have done.
    tasks = copy.deepcopy(LIVING)
    tasks[2]["after"] = [{"task": "screed", "type": "FF", "lag": 10}]
    run = {"tasks": tasks, "robots": ROBOTS, "start": START, "reasoner": "rules"}
    parent = completed_run(client, {**run, "mode": "success_focused"})
    assert rows_of(client.get(f"/runs/{parent}/schedule").json())["trowel"] == (45, 60)
    revised = client.post(
        f"/runs/{parent}/revisions",
        json={"reason": "no screed", "changes": [{"type": "remove_tasks", "task_ids": ["screed"]}]},
    )
    assert revised.status_code == 202, revised.text
    revision = revised.json()["id"]
    wait_status(client, revision, "completed")
    after = rows_of(client.get(f"/runs/{revision}/schedule").json())
    assert set(after) == {"pour", "trowel"}
    # The revision plans from its arrival (no `now` sent): the times relative to the pour.
    zero = after["pour"][0]
    assert after["pour"][1] - zero == pytest.approx(40)
    assert (after["trowel"][0] - zero, after["trowel"][1] - zero) == pytest.approx((15, 30))
