"""The task-boundary saver (app.graph.checkpoint._sparse): one checkpoint per task on disk;
a crash at any node, before or after its body, resumes at the start of the task it was in
and ends with an uninterrupted run's decisions, no LLM call paid twice; a review's pause
survives a new process."""

from __future__ import annotations

import sqlite3
from pathlib import Path
from typing import Any

import pytest
from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenario
from app.domain.problem import Problem
from app.domain.review import Resolution, ReviewAction, ReviewOn, ReviewPolicy
from app.graph.builder import NODES, TASK_START, build_graph
from app.graph.checkpoint import TaskBoundarySqliteSaver
from app.graph.memory_recorder import MemoryRecorder
from app.graph.runner import INTERRUPT_KEY, pending_interrupt, run_graph
from app.graph.state import GraphContext, LTAAState, Node
from app.reasoners.rules import RulesReasoner, compose_answer
from app.solvers.ltaa import graph_context
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner
from tests.support.ltaa_support import problem

PROBLEM = problem()
RETRY_TASK = 5  # its first answer is garbage: build_feedback and retry run there


class Crash(Exception):
    """Stands in for kill -9 inside a node."""


def saver(path: Path) -> TaskBoundarySqliteSaver:
    s = TaskBoundarySqliteSaver(
        sqlite3.connect(path, check_same_thread=False), boundary=(TASK_START,)
    )
    s.setup()
    s.conn.execute("PRAGMA synchronous=NORMAL")
    return s


def reasoner() -> ScriptedReasoner:
    def answer(ctx: Any) -> str:
        return GARBAGE if ctx.task_index == RETRY_TASK and ctx.tier == 0 else compose_answer(ctx)

    return ScriptedReasoner(then=answer)


def crash_at(task: int, node: str, after: bool, fired: list[bool]) -> Any:
    def hook(name: str, body: Node) -> Node:
        if name != node:
            return body

        def wrapped(state: LTAAState, runtime: Any) -> dict[str, Any]:
            hit = state["task_index"] == task and not fired
            if hit and not after:
                fired.append(True)
                raise Crash(f"before {node}")
            update = body(state, runtime)
            if hit and after:
                fired.append(True)
                raise Crash(f"after {node}")
            return update

        return wrapped

    return hook


def reference() -> tuple[list[int], int]:
    rec, scripted = MemoryRecorder(), reasoner()
    ctx = GraphContext(problem=PROBLEM, reasoner=scripted, recorder=rec)
    run_graph(build_graph(InMemorySaver()), ctx, "ref", resume=False)
    return [d.robot for d in rec.decisions()], len(scripted.calls)


@pytest.mark.parametrize("after", [False, True], ids=["before", "after"])
@pytest.mark.parametrize("node", sorted(NODES))
def test_a_crash_at_any_node_resumes_at_its_task_and_changes_nothing(
    tmp_path: Path, node: str, after: bool
) -> None:
    robots, calls = reference()
    rec, scripted = MemoryRecorder(), reasoner()
    fired: list[bool] = []
    ctx = GraphContext(problem=PROBLEM, reasoner=scripted, recorder=rec)
    first = saver(tmp_path / "cp.sqlite")
    with pytest.raises(Crash):
        run_graph(
            build_graph(first, node_hook=crash_at(RETRY_TASK, node, after, fired)),
            ctx,
            "run",
            resume=False,
        )
    first.conn.close()
    second = saver(tmp_path / "cp.sqlite")  # a new process: only what is on disk
    latest = second.get_tuple({"configurable": {"thread_id": "run"}})
    assert latest is not None
    assert latest.checkpoint["channel_values"]["task_index"] == RETRY_TASK
    final = run_graph(build_graph(second), ctx, "run", resume=True)
    assert final["done"] and final["task_index"] == PROBLEM.instance.n_tasks
    assert [d.robot for d in rec.decisions()] == robots
    assert len(scripted.calls) == calls  # every attempt asked once, however often re-run


def test_one_checkpoint_per_task_reaches_the_disk(tmp_path: Path) -> None:
    s = saver(tmp_path / "cp.sqlite")
    s.keep_latest = 10_000  # no pruning: count what was written
    ctx = GraphContext(problem=PROBLEM, reasoner=RulesReasoner(), recorder=MemoryRecorder())
    run_graph(build_graph(s), ctx, "run", resume=False)
    rows = s.conn.execute("select count(*) from checkpoints").fetchone()[0]
    writes = s.conn.execute("select count(*) from writes").fetchone()[0]
    n = PROBLEM.instance.n_tasks
    # The input, one where each task begins, the last one; no node writes.
    assert rows <= n + 3, rows
    assert writes == 0


def test_a_review_pause_survives_a_new_process(tmp_path: Path) -> None:
    review = ReviewPolicy(on=(ReviewOn.EVERY_DECISION,))
    base = Problem.build(scenario("baseline").instance)

    def context() -> GraphContext:
        return graph_context(
            base,
            reasoner=RulesReasoner(),
            recorder=rec,
            quality_threshold=0.6,
            max_retries=3,
            guidance=None,
            review=review,
        )

    rec = MemoryRecorder()
    first = saver(tmp_path / "cp.sqlite")
    paused = run_graph(build_graph(first), context(), "t", resume=False)
    payload = paused[INTERRUPT_KEY][0].value
    first.conn.close()

    second = saver(tmp_path / "cp.sqlite")
    graph = build_graph(second)
    assert pending_interrupt(graph, "t") == payload
    answer = Resolution(
        action=ReviewAction.APPROVE,
        reviewer="Dana",
        at="2026-12-01T21:00:00+00:00",
        triggers=("every_decision",),
    ).to_json()
    nxt = run_graph(graph, context(), "t", resume=True, resume_with=answer)
    assert nxt[INTERRUPT_KEY][0].value["task_index"] == 1
    assert [d.task_index for d in rec.decisions()] == [0]
