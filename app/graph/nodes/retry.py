"""Node 6, retry: escalate to the next prompt tier, or give up and ask for the fallback."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.graph.context import decision_context
from app.graph.nodes.common import cancellable, require_attempt, save_prompt, timing
from app.graph.prompts import retry_prompt
from app.graph.state import GraphContext, LTAAState

MAX_TIER = 3


@cancellable
def retry(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    rec = ctx.recorder
    t, a = state["task_index"], state["attempt"]
    if a >= ctx.max_attempts:
        return {"fallback": True}
    previous = require_attempt(rec, t, a)
    attempt = a + 1
    tier = min(attempt - 1, MAX_TIER)
    dctx = decision_context(
        ctx.problem, state, tier=tier, rate_notes=ctx.rate_notes, **timing(ctx, state)
    )
    user = retry_prompt(
        dctx,
        tier,
        previous.feedback or "",
        previous.quality,
        ctx.quality_threshold,
        ctx.model_use.reply_format,
    )
    save_prompt(rec, t, attempt, tier, user, ctx.model_use.reply_format)
    return {"attempt": attempt, "tier": tier}
