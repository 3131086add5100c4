"""Node 3, reason: one reasoner call per attempt, ever; none once the run has given its model
up (app.reasoners.give_up), when the rules reasoner answers instead.

A reply already recorded for (task, attempt) is reused, so re-running this node after a
crash never pays twice. The reply is saved the moment it arrives.
"""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.graph.context import decision_context
from app.graph.nodes.common import cancellable, require_attempt, timing
from app.graph.reply_schema import decision_schema
from app.graph.state import GraphContext, LTAAState
from app.reasoners.attribution import Why, attributed, stood_in
from app.reasoners.base import ReasonerError, ReasonerReply
from app.reasoners.give_up import GaveUp, given_up
from app.reasoners.rules import RulesReasoner

RULES = RulesReasoner()
GAVE = Why.GAVE_UP


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
    failing = state.get("failing", 0)
    try:
        if given_up(failing, ctx.model_use.give_up_after):
            # The record says so once; the rule answers, marked as standing in.
            rec.model_gave_up(GaveUp(t, failing, ctx.model_use.give_up_after))
            reply = stood_in(RULES.reason(record.system_prompt, record.user_prompt, dctx), GAVE)
        else:
            schema = decision_schema(dctx) if ctx.model_use.reply_format.structured else None
            reply = attributed(
                ctx.reasoner.reason(record.system_prompt, record.user_prompt, dctx, schema),
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
