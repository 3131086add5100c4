"""Node 3, reason: one reasoner call per attempt, ever.

A reply already recorded for (task, attempt) is reused, so re-running this node after a
crash never pays twice. The reply is saved the moment it arrives.
"""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.graph.context import decision_context
from app.graph.nodes.common import cancellable, require_attempt, timing
from app.graph.state import GraphContext, LTAAState
from app.reasoners.attribution import attributed
from app.reasoners.base import ReasonerError, ReasonerReply


@cancellable
def reason(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    rec = ctx.recorder
    t, a = state["task_index"], state["attempt"]
    record = require_attempt(rec, t, a)
    if record.reply is not None:
        return {}
    rec.before_reason(t, a)
    dctx = decision_context(ctx.problem, state, tier=state["tier"], **timing(ctx, state))
    try:
        reply = attributed(
            ctx.reasoner.reason(record.system_prompt, record.user_prompt, dctx),
            ctx.reasoner.name,
        )
    except ReasonerError as exc:
        # Transport gave up (after its own retries): a failed attempt, not a failed run.
        # No model answered, so the reply names none and is not counted as an LLM call.
        reply = ReasonerReply(
            text="",
            transport_retries=exc.transport_retries,
            extra={"error": str(exc) or type(exc).__name__, "reasoner": ctx.reasoner.name},
        )
    record.reply = reply
    rec.save_attempt(record)
    return {}
