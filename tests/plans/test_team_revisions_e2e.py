"""A team run revised on the real server (docs/living-plans.md#teams-in-a-revision): the site
reports a team task done and another started, a member of the started team breaks down, and the
revision, SIGKILLed while reasoning about a team decision and restarted, resumes to the same plan
as the same revision of an identical run left alone: the done team pinned whole, the started team
re-formed without the lost robot, every chain verified."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from app.graph.pause import PausePoint
from tests.runs.test_team_runs_e2e import BODY, KINDS
from tests.support.server import Server

pytestmark = pytest.mark.e2e

HELD_AT = 6  # a "Fix panel" team task, decided afresh by the revision
REPORTS = {
    "updates": [
        {"task_id": "t0", "state": "started", "at": "2026-12-01T08:00:00Z"},
        {"task_id": "t0", "state": "done", "at": "2026-12-01T08:40:00Z"},
        {"task_id": "t2", "state": "started", "at": "2026-12-01T08:10:00Z"},
    ]
}


def _completed(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def _members(a: dict[str, Any]) -> list[str]:
    return [m["robot"] for m in a["team"]] if a.get("team") else [a["robot"]]


def _plan(state: dict[str, Any]) -> list[tuple[Any, str, Any, bool]]:
    return [(a["task_id"], a["robot"], a.get("team"), a["pinned"]) for a in state["assignments"]]


def _revise(server: Server, run_id: str, gone: str) -> str:
    with server.client() as c:
        r = c.post(
            f"/runs/{run_id}/revisions",
            json={"changes": [{"type": "robot_unavailable", "robot": gone}], "reason": "fault"},
        )
    assert r.status_code == 202, r.text
    return str(r.json()["id"])


def test_a_team_revision_killed_mid_team_decision_resumes_to_the_same_plan(
    tmp_path: Path,
) -> None:
    first = Server(tmp_path / "data").start()
    try:
        parents = []
        for _ in range(2):
            with first.client() as c:
                created = c.post("/runs", json=BODY)
            assert created.status_code == 202, created.text
            parents.append(first.wait_for(created.json()["id"], _completed))
            with first.client() as c:
                sent = c.post(f"/runs/{parents[-1]['id']}/execution", json=REPORTS)
            assert sent.status_code == 200, sent.text
    finally:
        first.stop()
    parent = parents[0]
    assert _plan(parents[0]) == _plan(parents[1])
    t0, t2 = parent["assignments"][0], parent["assignments"][2]
    gone = next(r for r in _members(t2) if r not in _members(t0))

    held = PausePoint(HELD_AT, "reason", after=False)
    second = Server(tmp_path / "data").start(pause=held)
    try:
        revision = _revise(second, parent["id"], gone)
        state = second.wait_for(revision, lambda s: s["progress"]["allocated"] >= HELD_AT)
        second.wait_for_log(held.message())
    finally:
        second.kill()
    assert state["status"] == "running"

    third = Server(tmp_path / "data").start()
    try:
        resumed = third.wait_for(revision, _completed)
        reference = third.wait_for(_revise(third, parents[1]["id"], gone), _completed)
        with third.client() as c:
            trace = c.get(f"/runs/{revision}/trace").json()
            verify = c.get(f"/runs/{revision}/trace/verify").json()
            estimates = c.get("/sites/default/estimates").json()
    finally:
        third.stop()

    assert _plan(resumed) == _plan(reference)
    assert resumed["resumes"] == 1 and verify["ok"], verify
    integrity = next(e for e in trace["events"] if e["kind"] == "resumed")["detail"]["integrity"]
    assert integrity["ok"] is True
    now = resumed["assignments"]
    assert now[0]["pinned"] and now[0]["team"] == t0["team"]  # done: the whole team kept
    assert not now[2]["pinned"] and gone not in _members(now[2])  # started: re-formed
    for a in now:
        kind = KINDS[int(str(a["task_id"])[1:]) % 4]
        robots = _members(a)
        assert len(set(robots)) == len(robots)
        if "team" in kind:
            assert [m["feature"] for m in a["team"]] == [
                f for f, n in kind["team"].items() for _ in range(n)
            ]
        if not a["pinned"]:
            assert gone not in robots
    # The done team task taught each of its two members once, per parent run that reported it.
    for m in t0["team"]:
        row = next(r for r in estimates["robots"] if r["robot"] == m["robot"])
        heavy = next(f for f in row["features"] if f["feature"] == m["feature"])
        assert heavy["successes"] == 2
