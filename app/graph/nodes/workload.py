"""Node 8, update_workload: loads, balance score and severity after the decision."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.domain.metrics import balance_score, severity
from app.graph.nodes.common import cancellable
from app.graph.state import GraphContext, LTAAState


@cancellable
def update_workload(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    robot = state["robot"]
    if robot is None:
        raise RuntimeError(f"task index {state['task_index']} reached update_workload undecided")
    loads = list(state["loads"])
    loads[robot] += 1
    target = ctx.problem.instance.target_load
    view = {
        **state["view"],
        "balance": balance_score(loads, target),
        "severity": severity(loads, target).value,
    }
    return {"loads": loads, "view": view}
