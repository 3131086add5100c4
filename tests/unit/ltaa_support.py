"""Shared builders for the LTAA graph tests."""

from __future__ import annotations

from dataclasses import replace

from langgraph.checkpoint.memory import InMemorySaver

from app.domain.catalog import scenario, teach_tasks
from app.domain.decision import DecisionContext
from app.domain.models import Instance
from app.domain.modes import Mode, strategic_weights
from app.domain.phases import Phase
from app.domain.problem import Problem
from app.graph.builder import build_graph
from app.graph.memory_recorder import MemoryRecorder
from app.graph.runner import run_graph
from app.graph.state import GraphContext
from app.reasoners.base import Reasoner
from app.reasoners.rules import RulesReasoner


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
) -> tuple[MemoryRecorder, dict]:
    rec = recorder or MemoryRecorder()
    ctx = GraphContext(
        problem=prob,
        reasoner=reasoner or RulesReasoner(),
        recorder=rec,
        quality_threshold=threshold,
        max_retries=max_retries,
    )
    final = run_graph(build_graph(InMemorySaver()), ctx, "test-thread", resume=False)
    return rec, final


def context(**overrides: object) -> DecisionContext:
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
    ctx = replace(base, **overrides)  # type: ignore[arg-type]
    if "phase" in overrides or "mode" in overrides:
        ctx = replace(ctx, weights=strategic_weights(ctx.mode, ctx.phase))
    return ctx
