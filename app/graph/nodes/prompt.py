"""Node 2, build_prompt: the tier-0 prompt of the task's first attempt."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.graph.context import decision_context
from app.graph.nodes.common import cancellable, save_prompt, timing
from app.graph.prompts import user_prompt
from app.graph.state import GraphContext, LTAAState


@cancellable
def build_prompt(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    dctx = decision_context(
        ctx.problem, state, tier=0, rate_notes=ctx.rate_notes, **timing(ctx, state)
    )
    user = user_prompt(dctx, ctx.model_use.reply_format)
    save_prompt(ctx.recorder, state["task_index"], 1, 0, user, ctx.model_use.reply_format)
    # A task's flags are reset where the task starts, not where the previous one ended:
    # fewer writes per task (each is a checkpoint row).
    return {"attempt": 1, "tier": 0, "fallback": False}
