"""Node 9, store_and_route: persist the decision, then move to the next task (or finish)."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.graph.nodes.common import cancellable, require_attempt
from app.graph.recorder import DecisionRecord
from app.graph.state import GraphContext, LTAAState, next_task
from app.reasoners.give_up import next_failing


@cancellable
def store_and_route(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    rec = ctx.recorder
    inst = ctx.problem.instance
    t, robot, d = state["task_index"], state["robot"], state["decision"]
    if robot is None or d is None:
        raise RuntimeError(f"task index {t} reached store_and_route without a decision")
    task = inst.tasks[t]
    members = tuple(d.get("team") or (robot,))
    team = None
    if d.get("team"):
        team = [
            {"robot": inst.robots[r].name, "feature": f}
            for f, r in zip(inst.units[t], members, strict=True)
        ]
    reasoning, tradeoff = d.get("reasoning"), d.get("tradeoff")
    if d.get("text_attempt") is not None:
        parsed = require_attempt(rec, t, d["text_attempt"]).parsed or {}
        reasoning, tradeoff = parsed.get("reasoning"), parsed.get("tradeoff")
    rec.save_decision(
        DecisionRecord(
            task_index=t,
            task_id=task.id,
            task_name=task.name,
            robot=robot,
            robot_name=inst.robots[robot].name,
            phase=d["phase"],
            expected_success=d["expected_success"],
            reasoning=reasoning or "",
            confidence=d["confidence"],
            tradeoff=tradeoff or "",
            quality=d["quality"],
            fallback=d["fallback"],
            attempts=d["attempts"],
            failure_log=list(d["failure_log"]),
            loads_before=list(d["loads_before"]),
            loads_after=list(state["loads"]),
            balance_before=d["balance_before"],
            balance_after=state["view"]["balance"],
            severity_after=state["view"]["severity"],
            regret=ctx.regret(t, d["loads_before"], members) if ctx.regret is not None else None,
            review=d.get("review"),
            team=team,
            **(d.get("time") or {}),
        )
    )
    # build_prompt resets the per-task flags; clearing the text scratch keeps the next
    # task's checkpoints small.
    if inst.timed:
        # Placed after the write: a write refused (a lost fence) leaves the timelines as
        # the record has them.
        progress = ctx.timed.at(ctx.problem, rec, t)
        progress.place(t, robot, tuple(d.get("team") or ()))
        following = progress.current()
    else:
        following = next_task(ctx.problem, t)  # pinned tasks are not the graph's to decide
    return {
        "task_index": following,
        "done": following >= inst.n_tasks,
        "decision": None,
        "failing": next_failing(
            state.get("failing", 0), d["fallback"], ctx.model_use.give_up_after
        ),
    }
