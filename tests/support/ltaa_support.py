"""Shared builders for the LTAA graph tests."""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import replace
from typing import Any, cast

from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenario, teach_tasks
from app.domain.decision import DecisionContext
from app.domain.models import Instance
from app.domain.modes import Mode, strategic_weights
from app.domain.phases import Phase
from app.domain.problem import Problem
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.recorder import AttemptRecord, Recorder
from app.graph.runner import run_graph
from app.graph.state import GraphContext, LTAAState, ModelUse
from app.reasoners.base import Reasoner, ReasonerReply
from app.reasoners.rules import RulesReasoner


def as_state(values: Mapping[str, Any]) -> LTAAState:
    """A plain dict as the graph's state. A node returns a plain dict update that LangGraph
    merges into the state untyped; this cast is where a test does that same merge."""
    return cast(LTAAState, dict(values))


def attempt_of(recorder: Recorder, task_index: int, attempt: int) -> AttemptRecord:
    """The recorded attempt, which the test expects to exist."""
    record = recorder.attempt(task_index, attempt)
    assert record is not None, f"no attempt {attempt} recorded for task {task_index}"
    return record


def reply_of(record: AttemptRecord) -> ReasonerReply:
    """The attempt's reply, which the test expects (a transport failure records one too)."""
    assert record.reply is not None, f"attempt {record.attempt} has no reply"
    return record.reply


def problem(
    name: str = "baseline",
    mode: Mode = Mode.BALANCED,
    n_tasks: int | None = None,
    max_deviation: float | None = None,
) -> Problem:
    inst = scenario(name).instance
    if n_tasks is not None:
        inst = Instance(tasks=teach_tasks()[:n_tasks], robots=inst.robots)
    return Problem.build(inst, mode, max_deviation)


def run(
    prob: Problem,
    reasoner: Reasoner | None = None,
    *,
    max_retries: int = 3,
    threshold: float = 0.6,
    recorder: MemoryRecorder | None = None,
    model_use: ModelUse | None = None,
) -> tuple[MemoryRecorder, dict]:
    rec = recorder or MemoryRecorder()
    ctx = GraphContext(
        problem=prob,
        reasoner=reasoner or RulesReasoner(),
        recorder=rec,
        quality_threshold=threshold,
        max_retries=max_retries,
        model_use=model_use or ModelUse(),
    )
    final = run_graph(build_graph(InMemorySaver()), ctx, "test-thread", resume=False)
    return rec, final


def context(**overrides: Any) -> DecisionContext:
    """A middle-phase balanced decision: S light .5 / medium .7 / heavy .9, loads 3/5/6."""
    base = DecisionContext(
        task_index=14,
        total_tasks=36,
        task_name="Double Forward",
        features=("heavy",),
        robot_names=("light", "medium", "heavy"),
        robot_labels=("Light Robot", "Medium Robot", "Heavy Robot"),
        success=(0.5, 0.7, 0.9),
        loads=(3, 5, 6),
        target=12.0,
        feasible=(0, 1, 2),
        phase=Phase.MIDDLE,
        mode=Mode.BALANCED,
        weights=strategic_weights(Mode.BALANCED, Phase.MIDDLE),
        task_type="Motion",
        load_bounds=(8, 16),
    )
    ctx = replace(base, **overrides)
    if "phase" in overrides or "mode" in overrides:
        ctx = replace(ctx, weights=strategic_weights(ctx.mode, ctx.phase))
    return ctx
