"""A durable untimed team run against the real server (docs/allocation.md#teams): SIGKILLed while
reasoning about a team decision and restarted, it resumes to the same plan (members included) as an
uninterrupted run; its trace lists each team decision's members and its chain verifies."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from app.graph.pause import PausePoint
from tests.support.server import Server

pytestmark = pytest.mark.e2e

ROBOTS = [
    {"name": "crane", "success": {"heavy": 0.9, "careful": 0.2}, "skills": ["heavy"]},
    {"name": "arm", "success": {"heavy": 0.3, "careful": 0.95}},
    {"name": "lifter", "success": {"heavy": 0.8, "careful": 0.4}},
    {"name": "rigger", "success": {"heavy": 0.7, "careful": 0.6}},
]
KINDS: list[dict[str, Any]] = [
    {"name": "Lift beam", "team": {"heavy": 2}},
    {"name": "Sweep", "features": ["careful"]},
    {"name": "Fix panel", "team": {"heavy": 1, "careful": 1}},
    {"name": "Carry", "features": ["heavy"]},
]
BODY = {
    "tasks": [{"id": f"t{k}", **KINDS[k % 4]} for k in range(16)],
    "robots": ROBOTS,
    "mode": "balanced",
    "reasoner": "rules",
}
HELD_AT = 10  # a "Fix panel" team task


def _create(server: Server) -> str:
    with server.client() as c:
        response = c.post("/runs", json=BODY)
    assert response.status_code == 202, response.text
    return str(response.json()["id"])


def _completed(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def _plan(state: dict[str, Any]) -> list[tuple[Any, str, Any]]:
    return [(a["task_id"], a["robot"], a.get("team")) for a in state["assignments"]]


def test_a_team_run_killed_mid_team_decision_resumes_to_the_same_plan(tmp_path: Path) -> None:
    held = PausePoint(HELD_AT, "reason", after=False)
    first = Server(tmp_path / "data").start(pause=held)
    try:
        run_id = _create(first)
        state = first.wait_for(run_id, lambda s: s["progress"]["allocated"] >= HELD_AT)
        first.wait_for_log(held.message())  # held inside the team task's reasoning node
    finally:
        first.kill()
    assert state["status"] == "running"

    second = Server(tmp_path / "data").start()
    try:
        resumed = second.wait_for(run_id, _completed)
        reference = second.wait_for(_create(second), _completed)
        with second.client() as c:
            trace = c.get(f"/runs/{run_id}/trace").json()
            verify = c.get(f"/runs/{run_id}/trace/verify").json()
    finally:
        second.stop()

    assert _plan(resumed) == _plan(reference)
    assert resumed["resumes"] == 1 and reference["resumes"] == 0
    assert verify["ok"], verify
    decisions = trace["decisions"]
    assert [d["task_index"] for d in decisions] == list(range(16))
    for d in decisions:
        kind = KINDS[d["task_index"] % 4]
        if "team" in kind:
            units = [f for f, n in kind["team"].items() for _ in range(n)]
            assert [m["feature"] for m in d["team"]] == units, d
            robots = [m["robot"] for m in d["team"]]
            assert len(set(robots)) == len(robots) and robots[0] == d["robot"]
            assert all(m["robot"] != "crane" for m in d["team"] if m["feature"] == "careful")
        else:
            assert d.get("team") is None
    integrity = next(e for e in trace["events"] if e["kind"] == "resumed")["detail"]["integrity"]
    assert integrity["ok"] is True and integrity["resume_at_task"] == HELD_AT
    loads = resumed["workload"]
    assert sum(loads.values()) == 24  # 16 tasks, 24 units: each member counted
