"""Time in living plans through the API (docs/living-plans.md#a-revision-in-time): `now` and `delay`
on revisions, bad input refused with nothing stored."""

from __future__ import annotations

from datetime import datetime, timedelta
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.domain.catalog import timed_scenario
from app.domain.serialize import instance_to_dict
from tests.plans.test_revisions import completed_run, wait_status
from tests.support.clients import ClientFactory
from tests.support.polling import eventually
from tests.support.time_rules import TimeRules, site_history, slots_of

UNTIMED = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}


def nothing_stored(client: TestClient, parent: str, runs_before: int) -> None:
    state = client.get(f"/runs/{parent}").json()
    assert state["superseded_by"] is None and state["status"] == "completed"
    assert [r["id"] for r in client.get(f"/runs/{parent}/revisions").json()] == [parent]
    assert len(client.get("/runs").json()) == runs_before


@pytest.mark.parametrize(
    ("body", "loc", "words"),
    [
        (
            {"changes": [{"type": "delay", "task_id": 3, "minutes": 10}]},
            ["body", "changes", 0],
            "not timed",
        ),
        (
            {"changes": [{"type": "delay", "task_id": 3, "minutes": 0}]},
            ["body", "changes", 0, "delay", "minutes"],
            "greater than 0",
        ),
        (
            {"changes": [{"type": "delay", "task_id": 3, "minutes": -5}]},
            ["body", "changes", 0, "delay", "minutes"],
            "greater than 0",
        ),
        ({"now": "2026-12-01T09:30:00"}, ["body", "now"], "offset"),
        ({"now": "tomorrow"}, ["body", "now"], "RFC 3339"),
        ({"now": 1764581400}, ["body", "now"], "RFC 3339"),
    ],
)
def test_bad_time_input_on_an_untimed_run_is_a_422_naming_the_field(
    client: TestClient, body: dict[str, Any], loc: list[Any], words: str
) -> None:
    parent = completed_run(client, UNTIMED)
    runs_before = len(client.get("/runs").json())
    response = client.post(f"/runs/{parent}/revisions", json={"reason": "test", **body})
    assert response.status_code == 422, response.text
    detail = response.json()["detail"]
    assert [d["loc"] for d in detail] == [loc], detail
    assert words in detail[0]["msg"], detail
    nothing_stored(client, parent, runs_before)


def test_now_on_an_untimed_run_changes_nothing(client: TestClient) -> None:
    parent = completed_run(client, UNTIMED)
    body = {"reason": "heavy down", "changes": [{"type": "robot_unavailable", "robot": "heavy"}]}
    plain = client.post(f"/runs/{parent}/revisions", json={**body, "pin": "decided"})
    assert plain.status_code == 202, plain.text
    other = completed_run(client, UNTIMED)
    timed = client.post(
        f"/runs/{other}/revisions",
        json={**body, "pin": "decided", "now": "2026-12-01T09:30:00Z"},
    )
    assert timed.status_code == 202, timed.text
    a = wait_status(client, plain.json()["id"], "completed")
    b = wait_status(client, timed.json()["id"], "completed")
    assert [(x["task_id"], x["robot"]) for x in a["assignments"]] == [
        (x["task_id"], x["robot"]) for x in b["assignments"]
    ]
    diff = client.get(f"/runs/{timed.json()['id']}/diff").json()
    assert diff["schedule"] is None


# -- timed runs -----------------------------------------------------------------------------

TIMED = {"scenario": "baseline_timed", "reasoner": "rules"}
INSTANCE = timed_scenario("baseline_timed").instance
START = INSTANCE.start
TASKS = instance_to_dict(INSTANCE)["tasks"]
SUCCESSORS = {
    str(p): [str(t["id"]) for t in TASKS if p in t.get("after", ())]
    for p in (t["id"] for t in TASKS)
}
LATE_BY = 25.0


def at(minute: float) -> str:
    assert START is not None
    return (START + timedelta(minutes=minute)).isoformat()


def schedule(client: TestClient, run_id: str) -> dict[str, Any]:
    response = client.get(f"/runs/{run_id}/schedule")
    assert response.status_code == 200, response.text
    return dict(response.json())


def timed_parent(client: TestClient) -> tuple[str, dict[str, Any]]:
    run_id = completed_run(client, TIMED)
    return run_id, schedule(client, run_id)


def test_a_late_report_moves_the_successors_in_the_runs_schedule(client: TestClient) -> None:
    run_id, planned = timed_parent(client)
    reported = [str(t.id) for t in INSTANCE.tasks[:11]]
    history = site_history(planned, reported, SUCCESSORS, START, LATE_BY)
    response = client.post(f"/runs/{run_id}/execution", json={"updates": history.updates})
    assert response.status_code == 200, response.text
    now = schedule(client, run_id)
    before, after = slots_of(planned), slots_of(now)
    # Nobody changed robot; the reported tasks are where the site says; the rules of
    # docs/living-plans.md#a-revision-in-time hold.
    assert {t: s[0] for t, s in after.items()} == {t: s[0] for t, s in before.items()}
    rules = TimeRules(parent_tasks=TASKS, reports=history.reports, now=0.0)
    assert rules.broken(after) == []
    late_end = history.reports[history.late].end
    assert late_end is not None and late_end == before[history.late][2] + LATE_BY
    waiting = history.waiting
    assert waiting and all(after[s][1] >= late_end for s in waiting)
    assert any(after[s][1] > before[s][1] for s in waiting)
    assert now["makespan"] >= planned["makespan"]
    # The CSV reads the same times.
    csv = client.get(f"/runs/{run_id}/schedule", params={"format": "csv"}).text
    assert at(late_end) in csv
    # So does the console's Gantt chart: the makespan it names is the current one.
    page = client.get(f"/console/runs/{run_id}")
    assert page.status_code == 200
    assert now["makespan"] > planned["makespan"]  # here the delay reaches the last task
    assert f"makespan of {now['makespan']:,.0f} min" in page.text


def test_a_timed_revision_at_now_keeps_reports_delays_and_the_diff_shows_it(
    any_db_client: TestClient,
) -> None:
    client = any_db_client
    parent, planned = timed_parent(client)
    reported = [str(t.id) for t in INSTANCE.tasks[:11]]
    history = site_history(planned, reported, SUCCESSORS, START, LATE_BY)
    assert client.post(f"/runs/{parent}/execution", json={"updates": history.updates}).is_success
    current = schedule(client, parent)
    now = max(r.start for r in history.reports.values()) + 5
    delayed = next(
        str(t["id"]) for t in TASKS if str(t["id"]) not in reported and SUCCESSORS[str(t["id"])]
    )
    delay_key: Any = int(delayed) if delayed.isdigit() else delayed
    body = {
        "now": at(now),
        "changes": [
            {"type": "delay", "task_id": delay_key, "minutes": 30},
            {"type": "robot_unavailable", "robot": "heavy"},
        ],
        "reason": "heavy robot hydraulic fault; the pour runs late",
    }
    runs_before = len(client.get("/runs").json())
    done = next(t for t, r in history.reports.items() if r.state == "done")
    refusals: list[tuple[dict[str, Any], str]] = [
        ({"changes": [{"type": "delay", "task_id": "nope", "minutes": 5}]}, "changes.0.task_id"),
        ({"changes": [{"type": "delay", "task_id": int(done), "minutes": 5}]}, "changes.0.task_id"),
        ({"now": at(-1)}, "now"),
    ]
    for bad, loc in refusals:
        refused = client.post(f"/runs/{parent}/revisions", json={**body, **bad})
        assert refused.status_code == 422, refused.text
        (detail,) = refused.json()["detail"]
        assert ".".join(str(p) for p in detail["loc"][1:]) == loc, detail
    state = client.get(f"/runs/{parent}").json()
    assert state["superseded_by"] is None
    assert len(client.get("/runs").json()) == runs_before

    created = client.post(f"/runs/{parent}/revisions", json=body)
    assert created.status_code == 202, created.text
    revision = created.json()["id"]
    wait_status(client, revision, "completed")
    revised = schedule(client, revision)
    robots = {t: s[0] for t, s in slots_of(current).items()}
    kept = {
        t: r
        for t, r in history.reports.items()
        if not (r.state == "started" and robots[t] == "heavy")
    }
    rules = TimeRules(
        parent_tasks=TASKS,
        reports=kept,
        now=now,
        delays={delayed: 30.0},
        unavailable={"heavy"},
        parent_robots={t: robots[t] for t in kept},
    )
    after = slots_of(revised)
    assert rules.broken(after) == []
    late_end = history.reports[history.late].end
    assert late_end is not None
    # What waits for the late task and is not a reported fact waits for its real end.
    assert all(after[s][1] >= late_end for s in SUCCESSORS[history.late] if s not in kept)
    assert all(after[s][1] >= now for s in history.waiting)

    # The diff: every task whose times changed from the parent's current schedule, as they
    # are in the two schedules; the makespans; wall-clock times in the plan's offset.
    diff = client.get(f"/runs/{revision}/diff").json()["schedule"]
    before = slots_of(current)
    moved = {t for t in after if t in before and (after[t][1], after[t][2]) != before[t][1:]}
    assert {str(m["task_id"]) for m in diff["moves"]} == moved
    for m in diff["moves"]:
        t = str(m["task_id"])
        assert (m["robot_before"], m["start_before"], m["end_before"]) == before[t]
        assert (m["robot_after"], m["start_after"], m["end_after"]) == after[t]
        assert m["start_after_at"] == at(after[t][1]) and m["end_before_at"] == at(before[t][2])
        assert m["start_moved"] == after[t][1] - before[t][1]
    assert not {t for t, r in kept.items() if r.state == "done"} & moved
    assert delayed in moved
    assert diff["makespan_before"] == {
        "minutes": current["makespan"],
        "at": at(current["makespan"]),
    }
    assert diff["makespan_after"] == {"minutes": revised["makespan"], "at": at(revised["makespan"])}
    assert diff["makespan_after"]["minutes"] >= now
    # The record: the revision's first event says when it planned from and what it pinned.
    events = client.get(f"/runs/{revision}/trace").json()["events"]
    first = events[0]["detail"]
    assert datetime.fromisoformat(first["now"]) == datetime.fromisoformat(at(now))
    assert first["not_before"] == now
    assert set(first["pinned_times"]) == set(kept)
    assert client.get(f"/runs/{revision}/trace/verify").json()["ok"] is True


def test_a_running_timed_parent_revised_pins_its_reported_times(
    make_client: ClientFactory,
) -> None:
    """Revised while it holds before its last task in time order (Beep, queue position
    35): the pins the site reported carry their reported times in the revision's own
    decision rows, and the diff has no schedule block until both plans are whole."""
    client = make_client(test_pause="35:reason:before")
    parent = str(client.post("/runs", json=TIMED).json()["id"])
    eventually(
        lambda: client.get(f"/runs/{parent}").json()["progress"]["allocated"],
        until=lambda allocated: allocated >= 35,
        what="the parent decided every task but Beep",
    )
    decided = {
        str(a["task_id"]): a
        for a in client.get(f"/runs/{parent}", params={"limit": 1000}).json()["assignments"]
    }
    first = str(INSTANCE.tasks[0].id)
    begin, end = decided[first]["start"], decided[first]["end"] + LATE_BY
    updates = [
        {"task_id": INSTANCE.tasks[0].id, "state": "started", "at": at(begin)},
        {"task_id": INSTANCE.tasks[0].id, "state": "done", "at": at(end)},
    ]
    assert client.post(f"/runs/{parent}/execution", json={"updates": updates}).is_success
    created = client.post(
        f"/runs/{parent}/revisions", json={"reason": "late start", "now": at(end + 1)}
    )
    assert created.status_code == 202, created.text
    revision = created.json()["id"]
    assert client.get(f"/runs/{parent}").json()["status"] == "superseded"
    pins = [
        a
        for a in client.get(f"/runs/{revision}", params={"limit": 1000}).json()["assignments"]
        if a["pinned"]
    ]
    assert [(str(a["task_id"]), a["robot"]) for a in pins] == [(first, decided[first]["robot"])]
    assert (pins[0]["start"], pins[0]["end"]) == (begin, end)
    assert pins[0]["start_at"] == at(begin) and pins[0]["end_at"] == at(end)
    assert client.get(f"/runs/{revision}/diff").json()["schedule"] is None
    # Once the revision holds before Beep too (its record still while it waits), its
    # chain, reported pin included, verifies.
    eventually(
        lambda: client.get(f"/runs/{revision}").json()["progress"]["allocated"],
        until=lambda allocated: allocated >= 35,
        what="the revision decided every task but Beep",
    )
    verify = client.get(f"/runs/{revision}/trace/verify").json()
    assert verify["ok"] is True, verify
