"""The review gate inside the graph, with LangGraph's real checkpointer: the run pauses at
the end of finalize, a resume without a resolution leaves it paused without re-running the
node, and `Command(resume=...)` applies the resolution once."""

from __future__ import annotations

from collections import Counter
from typing import Any

from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenario
from app.domain.problem import Problem
from app.domain.review import Resolution, ReviewAction, ReviewOn, ReviewPolicy
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.runner import INTERRUPT_KEY, pending_interrupt, run_graph
from app.graph.state import GraphContext, LTAAState, Node
from app.reasoners.rules import RulesReasoner
from app.solvers.ltaa import graph_context


def _setup() -> tuple[Any, GraphContext, Counter[str]]:
    calls: Counter[str] = Counter()

    def count(name: str, node: Node) -> Node:
        def counted(state: LTAAState, runtime: Any) -> dict[str, Any]:
            calls[name] += 1
            return node(state, runtime)

        return counted

    graph = build_graph(InMemorySaver(), node_hook=count)
    problem = Problem.build(scenario("baseline").instance)
    ctx = graph_context(
        problem,
        reasoner=RulesReasoner(),
        recorder=MemoryRecorder(),
        quality_threshold=0.6,
        max_retries=3,
        guidance=None,
        review=ReviewPolicy(on=(ReviewOn.EVERY_DECISION,)),
    )
    return graph, ctx, calls


def test_the_graph_pauses_before_the_decision_is_stored_and_resumes_with_the_answer() -> None:
    graph, ctx, calls = _setup()
    result = run_graph(graph, ctx, "t", resume=False)
    payload = result[INTERRUPT_KEY][0].value
    assert payload["task_index"] == 0 and payload["triggers"] == ["every_decision"]
    assert ctx.recorder.decisions() == [] and calls["update_workload"] == 0
    assert pending_interrupt(graph, "t") == payload

    # A resume with no resolution (a restart) leaves it paused and re-runs nothing.
    before = dict(calls)
    again = run_graph(graph, ctx, "t", resume=True)
    assert again[INTERRUPT_KEY][0].value == payload and dict(calls) == before

    other = next(
        a["robot"] for a in payload["alternatives"] if a["robot"] != payload["proposal"]["robot"]
    )
    answer = Resolution(
        action=ReviewAction.OVERRIDE,
        reviewer="Dana",
        at="2026-12-01T21:00:00+00:00",
        triggers=("every_decision",),
        robot=other,
        reason="booked",
    ).to_json()
    nxt = run_graph(graph, ctx, "t", resume=True, resume_with=answer)
    assert nxt[INTERRUPT_KEY][0].value["task_index"] == 1  # the next decision waits in turn
    [decision] = ctx.recorder.decisions()
    assert decision.robot_name == other
    assert decision.review is not None and decision.review["overridden_from"] != other
    assert decision.loads_after[decision.robot] == 1
    assert calls["finalize"] == before["finalize"] + 2  # re-run once with the answer, then task 1
    assert calls["reason"] == 2  # never called again for task 0
