"""Node 4, validate: parse the reply and score the eight criteria against the true context."""

from __future__ import annotations

from typing import Any

from langgraph.runtime import Runtime

from app.domain.decision import DecisionContext
from app.graph.nodes.common import cancellable, current_attempt
from app.graph.recorder import AttemptRecord
from app.graph.state import GraphContext, LTAAState
from app.graph.validation import Validation, reasoner_failed, validate_text


def judge(record: AttemptRecord, dctx: DecisionContext, threshold: float) -> Validation:
    """The verdict on a recorded attempt (pure: build_feedback re-derives it the same way
    when validate's in-memory copy is gone, after a resume)."""
    reply = record.reply
    if reply is None:
        return reasoner_failed("no reply was recorded")
    error = reply.extra.get("error")
    if error:
        return reasoner_failed(str(error))
    return validate_text(reply.text, dctx, threshold)


@cancellable
def validate(state: LTAAState, runtime: Runtime[GraphContext]) -> dict[str, Any]:
    ctx = runtime.context
    record, dctx = current_attempt(ctx, state)
    verdict = judge(record, dctx, ctx.quality_threshold)
    ctx.verdicts.remember(state["task_index"], state["attempt"], verdict)
    record.parsed = verdict.parsed.to_dict(dctx.robot_names)
    record.scores = dict(verdict.scores)
    record.quality = verdict.quality
    record.accepted = verdict.accepted
    record.hard_invalid = verdict.hard_invalid
    ctx.recorder.save_attempt(record)
    return {"accepted": verdict.accepted, "robot": verdict.robot if verdict.accepted else None}
