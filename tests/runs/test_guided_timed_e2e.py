"""A guided timed run against the real server (docs/schedules.md#guidance-in-time): the run stores
the `schedule` solver's plan once, before its first decision; SIGKILLed while reasoning about a
decision in the middle and restarted, it reads that plan back (CP-SAT is not asked again: at a
wall-clock limit it may return another plan) and ends with the schedule an uninterrupted
guided run following the same plan makes."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import timed_scenario
from app.domain.problem import Problem
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.pause import PausePoint
from app.reasoners.rules import RulesReasoner
from app.solvers.ltaa import execute_ltaa
from app.solvers.timed_guidance import GuidancePlan
from tests.runs.test_timed_runs_e2e import spec16_violations
from tests.support.server import Server

pytestmark = pytest.mark.e2e

BODY = {"scenario": "baseline_timed", "reasoner": "rules", "guidance": "optimizer"}


def _completed(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def _uninterrupted(plan: GuidancePlan) -> list[tuple[str, str, float, float]]:
    """The guided run in-process, start to end, following `plan`: (task, robot, start, end)."""
    problem = Problem.build(timed_scenario("baseline_timed").instance)
    rec = MemoryRecorder()
    execute_ltaa(
        problem,
        graph=build_graph(InMemorySaver()),
        thread_id="reference",
        reasoner=RulesReasoner(),
        recorder=rec,
        quality_threshold=0.6,
        max_retries=3,
        guidance="optimizer",
        plan=plan,
    )
    robots = [r.name for r in problem.instance.robots]
    return sorted(
        (str(d.task_id), robots[d.robot], float(d.start or 0.0), float(d.end or 0.0))
        for d in rec.decisions()
    )


def test_a_guided_timed_run_killed_mid_run_resumes_on_its_stored_plan(tmp_path: Path) -> None:
    problem = Problem.build(timed_scenario("baseline_timed").instance)
    timing = problem.instance.timing
    # Which decision is about which task depends on the plan, which only the server
    # knows: hold a task with predecessors and successors, neither first nor last in any
    # precedence-respecting order, so the kill is mid-run whatever the plan.
    held = next(
        t
        for t in range(problem.instance.n_tasks)
        if timing.predecessors[t] and timing.successors[t]
    )
    held_at = PausePoint(held, "reason", after=False)
    first = Server(tmp_path / "data").start(pause=held_at)
    try:
        with first.client() as c:
            response = c.post("/runs", json=BODY)
            assert response.status_code == 202, response.text
            run_id = str(response.json()["id"])
        first.wait_for_log(held_at.message())
        stored = first.client().get(f"/runs/{run_id}").json()["progress"]["allocated"]
    finally:
        first.kill()
    assert 0 < stored < problem.instance.n_tasks

    second = Server(tmp_path / "data").start()
    try:
        state = second.wait_for(run_id, _completed)
        with second.client() as c:
            schedule = c.get(f"/runs/{run_id}/schedule").json()
            trace = c.get(f"/runs/{run_id}/trace").json()
            verify = c.get(f"/runs/{run_id}/trace/verify").json()
    finally:
        second.stop()

    assert state["resumes"] == 1
    # One plan, recorded once before the first decision: the resume did not solve again.
    planned = [e["detail"] for e in trace["events"] if e["kind"] == "guidance_planned"]
    assert len(planned) == 1
    plan = GuidancePlan.from_json(planned[0])
    assert len(plan.robots) == problem.instance.n_tasks
    # Decided in the plan's order: the held task came up after `stored` decisions.
    order = sorted(range(problem.instance.n_tasks), key=lambda t: (plan.starts[t], t))
    (resumed_event,) = [e for e in trace["events"] if e["kind"] == "resumed"]
    integrity = resumed_event["detail"]["integrity"]
    assert integrity["ok"] and integrity["decisions_stored"] == stored == order.index(held)
    assert integrity["resume_at_task"] == held
    assert spec16_violations(schedule) == []
    resumed = sorted(
        (str(s["task_id"]), str(s["robot"]), float(s["start"]), float(s["end"]))
        for s in schedule["tasks"]
    )
    assert resumed == _uninterrupted(plan)
    # The rules reasoner follows the plan: its robots, never later than its starts.
    names = [r.name for r in problem.instance.robots]
    index = {str(t.id): i for i, t in enumerate(problem.instance.tasks)}
    for s in schedule["tasks"]:
        t = index[str(s["task_id"])]
        assert s["robot"] == names[plan.robots[t]]
        assert s["start"] <= plan.starts[t] + 1e-6
    assert verify["ok"], verify
