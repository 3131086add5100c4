"""Node 1, detect_phase: progress, phase, balance, severity and strategic weights."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.graph.nodes.common import cancellable
from app.graph.state import GraphContext, LTAAState, task_view


@cancellable
def detect_phase(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    t, loads = state["task_index"], state["loads"]
    decided = later = None
    if ctx.problem.instance.timed:
        progress = ctx.timed.at(ctx.problem, ctx.recorder, t)
        decided = progress.decided
        later = progress.later(t)
    guided = ctx.guidance(t, tuple(loads)) if ctx.guidance is not None else None
    if guided is None or isinstance(guided, int):
        return {"view": task_view(ctx.problem, t, loads, guided, decided=decided, later=later)}
    costs = guided.costs if guided.team is None else None
    view = task_view(
        ctx.problem,
        t,
        loads,
        guided.robot,
        costs,
        decided=decided,
        guided_team=guided.team,
        later=later,
    )
    return {"view": view}
