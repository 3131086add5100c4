"""A run's token budget: once its LLM calls have spent it, the offline rules reasoner answers.

The check is made before each call: a call starts only while the tokens spent (input +
output of replies that name a model, as app.domain.usage counts them) are below the
budget, so a run spends at most the budget plus one call. The wrapper itself holds no
truth: whoever builds it seeds `spent` from the run's record, so a run restarted after a
crash switches at the same call, and `on_exhausted` must be idempotent (it may be told
again after a restart).
"""

from __future__ import annotations

from collections.abc import Callable
from dataclasses import asdict, dataclass
from typing import Any

from app.domain.decision import DecisionContext
from app.domain.lifecycle import EventKind
from app.reasoners.attribution import Why, stood_in
from app.reasoners.base import Reasoner, ReasonerReply, close_reasoner
from app.reasoners.rules import RulesReasoner
from app.reasoners.structured import ReplySchema

BUDGET_EXHAUSTED = EventKind.BUDGET_EXHAUSTED.value  # the run event recording the switch


@dataclass(frozen=True)
class BudgetExhausted:
    """When the switch happened: the first task answered by the rules reasoner."""

    task_index: int
    tokens_spent: int
    budget: int

    def as_dict(self) -> dict[str, Any]:
        return asdict(self)


class TokenBudgetReasoner:
    def __init__(
        self,
        inner: Reasoner,
        *,
        budget: int,
        spent: int,
        on_exhausted: Callable[[BudgetExhausted], None],
    ) -> None:
        self.name = inner.name  # failed calls are still attributed to the configured reasoner
        self.budget = budget
        self.spent = spent
        self._inner = inner
        self._rules = RulesReasoner()
        self._on_exhausted = on_exhausted
        self._told = False

    @property
    def exhausted(self) -> bool:
        return self.spent >= self.budget

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply:
        if not self.exhausted:
            reply = self._inner.reason(system, user, context, schema)
            if reply.model is not None:
                self.spent += reply.input_tokens + reply.output_tokens
            return reply
        if not self._told:
            self._on_exhausted(BudgetExhausted(context.task_index, self.spent, self.budget))
            self._told = True
        # The rules reply names no model (it is not an LLM call) and says why it answered.
        return stood_in(self._rules.reason(system, user, context), Why.BUDGET_EXHAUSTED)

    def close(self) -> None:
        close_reasoner(self._inner)
