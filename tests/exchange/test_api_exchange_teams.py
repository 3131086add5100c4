"""A timed team plan exported as MS Project XML (docs/exchange.md#export): MPXJ, the independent
oracle, reads the plan POST /allocate answers for `baseline_team` with `optimal` with its start
dates, one assignment per (task, member) over the task's own times (every member busy for all
of it, docs/allocation.md#teams) and its links; importing the export gives back the tasks,
durations, links and features, a one-feature team as a team of that many robots; and a durable
team run's export (GET /runs/{id}/schedule?format=mspdi) holds every member too."""

from __future__ import annotations

import itertools
from datetime import datetime
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.allocation.schemas import AllocateRequest
from app.allocation.service import build_problem, load_solver
from app.domain.catalog import timed_scenario
from app.exchange import write_mspdi
from tests.support.mpxj_oracle import read, to_datetime
from tests.support.polling import wait_until

pytestmark = pytest.mark.usefixtures("mpxj")

KINDS = {"FINISH_START": "FS", "START_START": "SS", "FINISH_FINISH": "FF", "START_FINISH": "SF"}
BODY: dict[str, Any] = {"solver": "optimal", "scenario": "baseline_team"}


def exported(client: TestClient) -> tuple[dict[str, Any], bytes]:
    """The plan POST /allocate answers, and its MSPDI export: the same one solve (the one
    `ltaa schedule baseline_team --method optimal --format mspdi` writes)."""
    answer = client.post("/allocate", json=BODY)
    assert answer.status_code == 200, answer.text
    problem = build_problem(AllocateRequest.model_validate(BODY))
    schedule = load_solver("optimal").solve(problem).details["schedule"]
    # The export's plan is the answer's: every task at the same start, on the same members.
    plan = answer.json()["schedule"]["tasks"]
    robots = problem.instance.robots
    assert [(row["start"], row.get("team")) for row in plan] == [
        (
            s.start,
            [
                {"robot": robots[m].name, "feature": f, "travel": s.travel_of(m)}
                for f, m in zip(problem.instance.units[s.task], s.team, strict=True)
            ]
            or None,
        )
        for s in schedule.slots
    ]
    return answer.json(), write_mspdi(problem, schedule, project_name="baseline_team: optimal")


def members(row: dict[str, Any]) -> list[str]:
    return [m["robot"] for m in row.get("team") or [{"robot": row["robot"]}]]


def test_mpxj_reads_every_team_member_of_a_timed_team_plans_export(client: TestClient) -> None:
    answer, data = exported(client)
    project = read(data)
    by_id = {str(t.getText(2)): t for t in project.getTasks() if t.getName() is not None}
    rows = answer["schedule"]["tasks"]
    assert len(by_id) == len(rows) == 36
    instance = timed_scenario("baseline_team").instance
    after = {str(t.id): sorted((str(p), "FS", 0.0) for p in t.after) for t in instance.tasks}
    teams = 0
    for row in rows:
        task = by_id[str(row["task_id"])]
        start = datetime.fromisoformat(row["start_at"]).replace(tzinfo=None)
        end = datetime.fromisoformat(row["end_at"]).replace(tzinfo=None)
        assert (to_datetime(task.getStart()), to_datetime(task.getFinish())) == (start, end)
        assignments = list(task.getResourceAssignments())
        assert [str(a.getResource().getName()) for a in assignments] == members(row)
        for a in assignments:  # every member over the task's own times
            assert (to_datetime(a.getStart()), to_datetime(a.getFinish())) == (start, end)
        teams += len(assignments) > 1
        links = sorted(
            (
                str(r.getPredecessorTask().getText(2)),
                KINDS[str(r.getType().name())],
                float(r.getLag().getDuration()),
            )
            for r in task.getPredecessors()
        )
        assert links == after[str(row["task_id"])]
    assert teams == 7  # baseline_team's seven team tasks, each with both members
    names = {str(r.getName()) for r in project.getResources() if r.getName() is not None}
    assert names == {"light", "medium", "heavy"}
    # A member's tasks in the file never overlap (no robot in two places at once).
    lanes: dict[str, list[tuple[datetime, datetime]]] = {}
    for a in project.getResourceAssignments():
        if a.getResource() is not None and a.getTask().getName() is not None:
            span = (to_datetime(a.getStart()), to_datetime(a.getFinish()))
            lanes.setdefault(str(a.getResource().getName()), []).append(span)
    for spans in lanes.values():
        spans.sort()
        assert all(a[1] <= b[0] for a, b in itertools.pairwise(spans)), spans


def test_the_team_plans_export_imports_back_to_its_tasks_and_teams(client: TestClient) -> None:
    answer, data = exported(client)
    draft = client.post("/schedules/import", content=data, params={"features_field": "Text1"})
    assert draft.status_code == 200, draft.text
    imported = {t["id"]: t for t in draft.json()["tasks"]}
    assert draft.json()["skipped"] == []
    instance = timed_scenario("baseline_team").instance
    by_row = {str(row["task_id"]): row for row in answer["schedule"]["tasks"]}
    for task in instance.tasks:
        got = imported[str(task.id)]
        assert got["name"] == task.name and got["features"] == list(task.features)
        assert got["after"] == [{"task": str(p), "type": "FS", "lag": 0} for p in task.after]
        assert got["planned_robots"] == members(by_row[str(task.id)])
        if task.team is not None:
            assert got["duration"] == task.duration
        # docs/exchange.md#export: several assigned resources on one feature read as a team; a
        # team over two features reads its members as the planner's intent only.
        if task.team is not None and len(task.team) == 1:
            assert got["team"] == task.team
        else:
            assert "team" not in got


def test_a_durable_timed_team_runs_export_holds_every_member(client: TestClient) -> None:
    """GET /runs/{id}/schedule?format=mspdi of a durable `baseline_team` run (the LTAA graph's
    own teams in time): MPXJ reads each task at the run's start with one assignment per member."""
    created = client.post("/runs", json={"scenario": "baseline_team", "reasoner": "rules"})
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    assert wait_until(client, run_id, timeout=120)["status"] == "completed"
    plan = client.get(f"/runs/{run_id}/schedule").json()["tasks"]
    exported = client.get(f"/runs/{run_id}/schedule", params={"format": "mspdi"})
    assert exported.status_code == 200, exported.text
    project = read(exported.content)
    by_id = {str(t.getText(2)): t for t in project.getTasks() if t.getName() is not None}
    assert len(by_id) == len(plan) == 36
    teams = 0
    for row in plan:
        task = by_id[str(row["task_id"])]
        start = datetime.fromisoformat(row["start_at"]).replace(tzinfo=None)
        assert to_datetime(task.getStart()) == start
        names = [str(a.getResource().getName()) for a in task.getResourceAssignments()]
        assert names == members(row)
        teams += len(names) > 1
    assert teams == 7
