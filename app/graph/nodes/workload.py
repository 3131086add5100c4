"""Node 8, update_workload: loads, balance score and severity after the decision."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.graph.nodes.common import cancellable
from app.graph.state import GraphContext, LTAAState, balance_of, severity_of


@cancellable
def update_workload(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    robot = state["robot"]
    if robot is None:
        raise RuntimeError(f"task index {state['task_index']} reached update_workload undecided")
    loads = list(state["loads"])
    # docs/allocation.md#teams: a team task adds one to each member's load.
    for member in (state.get("decision") or {}).get("team") or [robot]:
        loads[member] += 1
    view = {
        **state["view"],
        "balance": balance_of(ctx.problem, loads),
        "severity": severity_of(ctx.problem, loads),
    }
    return {"loads": loads, "view": view}
