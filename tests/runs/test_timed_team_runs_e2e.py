"""A durable timed team run against the real server (docs/allocation.md#teams,
docs/schedules.md#runs-in-time): `baseline_team` SIGKILLed while reasoning about a team decision
half-way through its time order and restarted resumes to the same plan, times and members
included, as an uninterrupted run; its trace lists each team decision's members, and its chain
verifies online and offline. One kill, one restart: the reference run shares the second server."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from app.domain.catalog import timed_scenario
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.graph.pause import PausePoint
from tests.support.ltaa_support import run
from tests.support.offline_check import check_offline
from tests.support.server import Server

pytestmark = pytest.mark.e2e

BODY = {"scenario": "baseline_team", "reasoner": "rules", "mode": "balanced"}


def _create(server: Server) -> str:
    with server.client() as c:
        response = c.post("/runs", json=BODY)
    assert response.status_code == 202, response.text
    return str(response.json()["id"])


def _completed(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def _plan(state: dict[str, Any]) -> list[tuple[Any, ...]]:
    return [
        (a["task_id"], a["robot"], a.get("team"), a["start"], a["end"])
        for a in state["assignments"]
    ]


def _team_decision_half_way() -> tuple[int, int]:
    """(task index, place in the time order) of the team decision nearest the run's middle,
    from the graph run in memory (the server decides the same: one deterministic rule)."""
    problem = Problem.build(timed_scenario("baseline_team").instance, Mode.BALANCED)
    rec, _ = run(problem)
    n = problem.instance.n_tasks
    team = [(d.task_index, d.seq or 0) for d in rec.decisions() if d.team]
    return min(team, key=lambda ts: abs(ts[1] - n // 2))


def test_a_timed_team_run_killed_mid_team_decision_resumes_to_the_same_plan(
    tmp_path: Path,
) -> None:
    task, seq = _team_decision_half_way()
    assert task != seq  # decided in time order, not queue order: a real place to die in
    held = PausePoint(task, "reason", after=False)
    first = Server(tmp_path / "data").start(pause=held)
    try:
        run_id = _create(first)
        first.wait_for(run_id, lambda s: bool(s["progress"]["allocated"] >= seq))
        first.wait_for_log(held.message())  # held inside the team task's reasoning node
    finally:
        first.kill()

    second = Server(tmp_path / "data").start()
    try:
        resumed = second.wait_for(run_id, _completed)
        reference = second.wait_for(_create(second), _completed)
        with second.client() as c:
            trace = c.get(f"/runs/{run_id}/trace").json()
            verify = c.get(f"/runs/{run_id}/trace/verify").json()
            export = c.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text
            schedule = c.get(f"/runs/{run_id}/schedule").json()
    finally:
        second.stop()

    assert resumed["resumes"] == 1 and reference["resumes"] == 0
    assert _plan(resumed) == _plan(reference)
    assert verify["ok"], verify
    path = tmp_path / "run.jsonl"
    path.write_text(export)
    offline = check_offline(path)
    assert offline.returncode == 0, offline.stdout + offline.stderr
    (event,) = [e for e in trace["events"] if e["kind"] == "resumed"]
    integrity = event["detail"]["integrity"]
    assert integrity["ok"] and integrity["decisions_stored"] == seq
    assert integrity["resume_at_task"] == task
    teams = {t.id: t.team for t in timed_scenario("baseline_team").instance.tasks if t.team}
    decided = {d["task_id"]: d for d in trace["decisions"]}
    assert len(decided) == 36
    for task_id, team in teams.items():
        members = decided[task_id]["team"]
        assert [m["feature"] for m in members] == [f for f, n in team.items() for _ in range(n)]
        names = [m["robot"] for m in members]
        assert len(set(names)) == len(names) and names[0] == decided[task_id]["robot"]
    # Each team task sits in every member's lane over the same minutes.
    by_id = {a["task_id"]: a for a in resumed["assignments"]}
    for task_id in teams:
        a = by_id[task_id]
        for m in a["team"]:
            lane = schedule["robots"][m["robot"]]["lane"]
            worked = [(i["start"], i["end"]) for i in lane if i.get("task_id") == task_id]
            assert (a["start"], a["end"]) in worked
