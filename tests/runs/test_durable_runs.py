"""Durable runs against the real server: SIGKILL mid-run, restart, nothing lost or doubled."""

from __future__ import annotations

import random
from collections.abc import Callable
from pathlib import Path
from typing import Any

import pytest

from app.graph.pause import PausePoint
from tests.support.server import TRANSIENT_POLL_S, Server

pytestmark = pytest.mark.e2e


def _create(server: Server, body: dict[str, Any]) -> str:
    with server.client() as c:
        response = c.post("/runs", json=body)
    assert response.status_code == 202, response.text
    assert response.headers["location"] == f"/runs/{response.json()['id']}"
    return str(response.json()["id"])


def _assignments(state: dict[str, Any]) -> list[tuple[Any, str]]:
    return [(a["task_id"], a["robot"]) for a in state["assignments"]]


def _allocated(at_least: int) -> Callable[[dict[str, Any]], bool]:
    def allocated(state: dict[str, Any]) -> bool:
        return bool(state["progress"]["allocated"] >= at_least)

    return allocated


def _completed(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def test_run_killed_at_task_18_resumes_at_task_18(tmp_path: Path) -> None:
    body = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
    held_at = PausePoint(18, "reason", after=False)
    first = Server(tmp_path / "data").start(pause=held_at)
    try:
        run_id = _create(first, body)
        state = first.wait_for(run_id, lambda s: s["progress"]["allocated"] >= 18)
        first.wait_for_log(held_at.message())  # held inside task 18's reasoning node
        assert first.client().get(f"/runs/{run_id}").json()["progress"]["allocated"] == 18
    finally:
        first.kill()
    assert state["status"] == "running"

    second = Server(tmp_path / "data").start()
    try:
        resumed = second.wait_for(run_id, _completed)
        reference_id = _create(second, body)
        reference = second.wait_for(reference_id, _completed)
        with second.client() as c:
            trace = c.get(f"/runs/{run_id}/trace").json()
    finally:
        second.stop()

    assert _assignments(resumed) == _assignments(reference)
    assert resumed["resumes"] == 1 and reference["resumes"] == 0
    indices = [d["task_index"] for d in trace["decisions"]]
    assert indices == list(range(36))
    resumed_events = [e for e in trace["events"] if e["kind"] == "resumed"]
    assert len(resumed_events) == 1
    integrity = resumed_events[0]["detail"]["integrity"]
    assert integrity["ok"] is True
    assert integrity["resume_at_task"] == 18
    assert integrity["decisions_stored"] == 18
    kinds = [e["kind"] for e in trace["events"]]
    assert kinds.index("interrupted") < kinds.index("resumed") < kinds.index("completed")


def _big_instance(n_tasks: int = 500, seed: int = 11) -> dict[str, Any]:
    rng = random.Random(seed)
    features = ["heavy", "dexterous", "careful"]
    robots = [
        {"name": f"r{i}", "success": {f: round(rng.uniform(0.3, 0.99), 2) for f in features}}
        for i in range(4)
    ]
    tasks = [
        {"id": t, "name": f"task {t}", "features": rng.sample(features, rng.randint(1, 2))}
        for t in range(n_tasks)
    ]
    return {"tasks": tasks, "robots": robots, "mode": "balanced", "reasoner": "rules"}


def test_three_sigkills_during_a_500_task_run(tmp_path: Path) -> None:
    body = _big_instance()
    rng = random.Random(2026)
    kill_points = sorted(rng.sample(range(20, 480), 3))
    data = tmp_path / "data"
    server = Server(data).start()
    run_id = _create(server, body)
    # Progress is polled with a one-assignment page: the full 500 at 20 Hz would cost the
    # server more than the run; the states compared are read whole once the runs completed.
    for point in kill_points:
        server.wait_for(run_id, _allocated(point), page=1, interval=TRANSIENT_POLL_S)
        server.kill()
        server = Server(data).start()
    try:
        server.wait_for(run_id, _completed, timeout=300, page=1)
        reference_id = _create(server, body)
        server.wait_for(reference_id, _completed, timeout=300, page=1)
        with server.client() as c:
            resumed = c.get(f"/runs/{run_id}").json()
            reference = c.get(f"/runs/{reference_id}").json()
            trace = c.get(f"/runs/{run_id}/trace").json()
    finally:
        server.stop()
    assert _assignments(resumed) == _assignments(reference)
    assert [d["task_index"] for d in trace["decisions"]] == list(range(500))
    assert resumed["resumes"] == 3
    assert sum(e["kind"] == "resumed" for e in trace["events"]) == 3
    assert all(e["detail"]["integrity"]["ok"] for e in trace["events"] if e["kind"] == "resumed")
