"""The pre-resume integrity check accepts every state a kill -9 can leave behind."""

from __future__ import annotations

from langgraph.checkpoint.memory import InMemorySaver

from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.runner import run_graph
from app.graph.state import GraphContext
from app.reasoners.rules import RulesReasoner
from app.runs.integrity import check_integrity
from tests.unit.ltaa_support import problem

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
