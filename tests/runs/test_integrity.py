"""The pre-resume integrity check accepts every state a kill -9 can leave behind."""

from __future__ import annotations

import bisect
from typing import Any

from langgraph.checkpoint.memory import InMemorySaver

from app.domain.problem import Problem
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.recorder import DecisionRecord
from app.graph.runner import run_graph
from app.graph.state import GraphContext
from app.reasoners.rules import RulesReasoner
from app.runs.integrity import IntegrityReport, check_integrity
from tests.support.ltaa_support import problem

PROBLEM = problem(n_tasks=12)


def test_every_checkpoint_of_a_run_is_consistent_with_the_decisions_then_stored() -> None:
    recorder = MemoryRecorder()
    graph = build_graph(InMemorySaver())
    context = GraphContext(problem=PROBLEM, reasoner=RulesReasoner(), recorder=recorder)
    run_graph(graph, context, "t", resume=False)
    decisions = recorder.decisions()
    snapshots = list(graph.get_state_history({"configurable": {"thread_id": "t"}}))
    assert len(snapshots) > 7 * 12  # one per super-step: seven per task without retries

    checked = 0
    for snapshot in snapshots:
        values = snapshot.values
        if "task_index" not in values:
            continue  # the input checkpoint, before START
        index = values["task_index"]
        # A kill after this checkpoint: store_and_route of task `index` may already have
        # committed its decision (if it was the node running), never a later one.
        stored_options = [index]
        if snapshot.next == ("store_and_route",):
            stored_options.append(index + 1)
        for stored in stored_options:
            report = check_integrity(
                decisions=decisions[:stored], n_tasks=12, n_robots=3, checkpoint=values
            )
            assert report.ok, (snapshot.next, stored, report.problems)
            checked += 1
    assert checked > len(snapshots)


def test_loads_that_disagree_with_the_decisions_are_reported() -> None:
    recorder = MemoryRecorder()
    graph = build_graph(InMemorySaver())
    context = GraphContext(problem=PROBLEM, reasoner=RulesReasoner(), recorder=recorder)
    run_graph(graph, context, "t", resume=False)
    decisions = recorder.decisions()
    values = dict(graph.get_state({"configurable": {"thread_id": "t"}}).values)
    values["task_index"] = 6
    values["robot"] = None
    values["loads"] = [6, 0, 0]
    report = check_integrity(decisions=decisions[:6], n_tasks=12, n_robots=3, checkpoint=values)
    assert not report.ok and "disagree" in report.problems[0]


def _pin(task_index: int, robot: int) -> DecisionRecord:
    return DecisionRecord(
        task_index=task_index,
        task_id=task_index,
        task_name="pinned",
        robot=robot,
        robot_name=str(robot),
        phase="early",
        expected_success=0.5,
        reasoning="",
        confidence="",
        tradeoff="",
        quality=1.0,
        fallback=False,
        attempts=0,
        failure_log=[],
        loads_before=[],
        loads_after=[],
        balance_before=0.0,
        balance_after=0.0,
        severity_after="low",
    )


def test_a_revision_resume_knows_its_pins() -> None:
    """Pins anywhere in the queue (a failed task between them stays free), one of them on
    a robot that is now unavailable: every checkpoint is consistent with the stored rows."""
    pins = {0: 0, 1: 1, 2: 2, 5: 0}
    pinned = Problem.build(PROBLEM.instance, PROBLEM.mode, pinned=pins, unavailable={2})
    recorder = MemoryRecorder()
    graph = build_graph(InMemorySaver())
    context = GraphContext(problem=pinned, reasoner=RulesReasoner(), recorder=recorder)
    run_graph(graph, context, "t", resume=False)
    free = recorder.decisions()
    assert [d.task_index for d in free] == list(pinned.free_tasks)
    assert all(d.robot != 2 for d in free)
    rows = [_pin(t, r) for t, r in pins.items()]

    def check(stored: list[DecisionRecord], values: dict[str, Any]) -> IntegrityReport:
        return check_integrity(
            decisions=sorted(stored, key=lambda d: d.task_index),
            n_tasks=12,
            n_robots=3,
            checkpoint=values,
            pinned=pinned.pinned,
            free_tasks=pinned.free_tasks,
            initial_loads=pinned.initial_loads,
            balance_robots=pinned.available,
            target=pinned.target,
        )

    checked = 0
    for snapshot in graph.get_state_history({"configurable": {"thread_id": "t"}}):
        values = snapshot.values
        if "task_index" not in values:
            continue
        position = bisect.bisect_left(pinned.free_tasks, values["task_index"])
        options = [position] + ([position + 1] if snapshot.next == ("store_and_route",) else [])
        for k in options:
            report = check(rows + free[:k], values)
            assert report.ok, (snapshot.next, k, report.problems)
            assert report.pinned == 4
            checked += 1
    assert checked > 8 * 7
    moved = [_pin(t, (r + 1) % 3) if t == 5 else _pin(t, r) for t, r in pins.items()]
    report = check(moved + free, {})
    assert not report.ok and "pinned" in report.problems[0]
