"""Which reasoner wrote each reply, and why the rules reasoner did when it stood in.

Every reply the graph records carries `reasoner` in its extra (`anthropic`, `openai`,
`rules`, `replay`); a reply from the rules reasoner standing in for the configured one
also carries `why`. Both live in the attempt's stored reply_extra, which the hash chain
already covers. Attempts recorded before this existed are attributed from what they did
store (attempt_attribution).
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, replace
from enum import StrEnum
from typing import Any

from app.reasoners.base import ReasonerReply

REASONER = "reasoner"
WHY = "why"
RULES = "rules"
REPLAY = "replay"


class Why(StrEnum):
    """Why the rules reasoner answered instead of the run's LLM."""

    CLEAR_CUT = "clear-cut"  # llm_scope 'contested': the decision was not contested
    BUDGET_EXHAUSTED = "budget_exhausted"  # the run's token budget was spent
    FALLBACK = "fallback"  # every attempt failed: the conservative fallback decided
    GAVE_UP = "gave_up"  # the model failed too many tasks in a row (app.reasoners.give_up)


def attributed(reply: ReasonerReply, reasoner: str) -> ReasonerReply:
    """`reply` naming `reasoner` as its writer, unless it names one already (a wrapper's
    stand-in reply names the rules reasoner)."""
    if REASONER in reply.extra:
        return reply
    return replace(reply, extra={REASONER: reasoner, **reply.extra})


def stood_in(reply: ReasonerReply, why: Why) -> ReasonerReply:
    """A rules reasoner's reply, marked as standing in for the run's reasoner."""
    return replace(reply, extra={**reply.extra, REASONER: RULES, WHY: why.value})


@dataclass(frozen=True)
class Attribution:
    reasoner: str
    why: str | None = None


def attempt_attribution(
    extra: Mapping[str, Any] | None, model: str | None, run_reasoner: str
) -> Attribution:
    """Who wrote a stored attempt's reply. Rows from before attribution are derived: a
    reply naming a model came from the run's reasoner, a replayed one from replay, and
    any other from the rules reasoner (a token budget's switch said so as `reason`)."""
    extra = extra or {}
    why = extra.get(WHY) or extra.get("reason")
    if extra.get(REASONER):
        return Attribution(str(extra[REASONER]), str(why) if why else None)
    if model is not None:
        return Attribution(run_reasoner)
    if "replayed_from" in extra:
        return Attribution(REPLAY)
    if run_reasoner == RULES:
        return Attribution(RULES)
    return Attribution(RULES, str(why) if why else None)


def decision_attribution(fallback: bool, accepted: Attribution | None) -> Attribution:
    """Who decided a task: the accepted attempt's reasoner, or the rules fallback."""
    if fallback or accepted is None:
        return Attribution(RULES, Why.FALLBACK.value)
    return accepted
