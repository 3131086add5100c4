"""Helpers shared by several nodes."""

from __future__ import annotations

import functools
from typing import Any

from langgraph.runtime import Runtime

from app.domain.decision import DecisionContext
from app.domain.scheduling.progress import TimeOption
from app.graph.context import decision_context
from app.graph.gate import NODE_GATE
from app.graph.prompts import system_prompt
from app.graph.recorder import AttemptRecord, Recorder
from app.graph.state import GraphContext, LTAAState, Node
from app.reasoners.structured import ReplyFormat


def cancellable(node: Node) -> Node:
    """Every node starts by checking for cancellation: a cancel, a drain or a lost lease
    stops the run at the next node boundary, before the node does anything. Every node
    body also runs inside the process's node gate, which a backup holds (app.graph.gate)."""

    @functools.wraps(node)
    def checked(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
        with NODE_GATE.passage():
            runtime.context.recorder.check_cancelled()
            return node(state, runtime)

    return checked


def save_prompt(
    recorder: Recorder,
    task_index: int,
    attempt: int,
    tier: int,
    user: str,
    fmt: ReplyFormat = ReplyFormat.MARKDOWN,
) -> None:
    """Record the prompt of an attempt, unless the attempt already has a reply.

    A node re-executed after a crash (or LangGraph bug #8039) must not wipe a reply
    that the reason node already paid for.
    """
    existing = recorder.attempt(task_index, attempt)
    if existing is not None and existing.reply is not None:
        return
    recorder.save_attempt(
        AttemptRecord(
            task_index=task_index,
            attempt=attempt,
            tier=tier,
            system_prompt=system_prompt(fmt),
            user_prompt=user,
        )
    )


def require_attempt(recorder: Recorder, task_index: int, attempt: int) -> AttemptRecord:
    record = recorder.attempt(task_index, attempt)
    if record is None:
        raise RuntimeError(
            f"no attempt {attempt} recorded for task index {task_index}; the "
            "recorder lost a write the graph relies on"
        )
    return record


def timing(ctx: GraphContext, state: LTAAState) -> dict[str, Any]:
    """decision_context's time arguments: on a timed instance, what each robot would make of
    the current task in time, and how many tasks are allocated before it; else none."""
    if not ctx.problem.instance.timed:
        return {}
    t = state["task_index"]
    progress = ctx.timed.at(ctx.problem, ctx.recorder, t)
    options: tuple[TimeOption, ...] = progress.options(t)
    out: dict[str, Any] = {
        "timing": options,
        "allocated": len(ctx.problem.pinned) + progress.decided,
    }
    if ctx.problem.instance.units[t]:
        # docs/allocation.md#teams: a team's time is its last member's arrival, not any one
        # robot's option; read while the progress still has `t` next (this node's lifetime).
        out["team_time"] = functools.partial(progress.team_option, t)
        out["later"] = progress.later(t)
    return out


def current_attempt(ctx: GraphContext, state: LTAAState) -> tuple[AttemptRecord, DecisionContext]:
    """The recorded attempt the state points at, and the true facts it is judged against."""
    record = require_attempt(ctx.recorder, state["task_index"], state["attempt"])
    return record, decision_context(ctx.problem, state, tier=state["tier"], **timing(ctx, state))
