"""`llm_scope: "contested"` (docs/reasoners.md#llm_scope-ask-the-model-only-where-it-matters): the
LLM is asked only where its judgement can matter.

Among the cap-feasible robots the trade-off rule picks `best` iff its gap over `fewest`
exceeds the mode/phase threshold T. A decision is contested when that verdict is close
to flipping (|gap - T| <= margin points) or when optimizer guidance names another robot
than the rule. Every other decision is clear-cut (one feasible robot, best = fewest, or a
gap far from T) and the rules reasoner answers it, its reply marked `why: "clear-cut"`.
The verdict depends only on the decision's facts, so a retry of a contested decision
asks the LLM again and a resumed run splits its decisions exactly as before.

A wrapper, composed like the token budget (app.reasoners.budget): validation, retries and
the fallback see its replies like any other reasoner's.
"""

from __future__ import annotations

from enum import StrEnum

from app.domain.decision import DecisionContext
from app.domain.team_choice import team_rule
from app.domain.tradeoff import rule_for
from app.reasoners.attribution import Why, stood_in
from app.reasoners.base import Reasoner, ReasonerReply, close_reasoner
from app.reasoners.rules import RulesReasoner
from app.reasoners.structured import ReplySchema

DEFAULT_LLM_MARGIN = 5.0  # points either side of the threshold


class LLMScope(StrEnum):
    ALL = "all"  # every decision asks the LLM (the paper)
    CONTESTED = "contested"  # only contested decisions do


def is_contested(ctx: DecisionContext, margin: float = DEFAULT_LLM_MARGIN) -> bool:
    if ctx.team is not None:  # docs/allocation.md#teams: the rule between two teams
        teams = team_rule(ctx)
        guided_team = ctx.team.guided
        if guided_team is not None and guided_team != teams.choice:
            return True
        if teams.best == teams.fewest:
            return False
        return abs(teams.rule.gap - teams.rule.threshold) <= margin
    if len(ctx.feasible) <= 1:
        return False
    rule = rule_for(ctx)
    guided = ctx.guided_robot
    if guided is not None and guided in ctx.feasible and guided != rule.choice:
        return True
    if rule.best == rule.fewest:
        return False
    return abs(rule.gap - rule.threshold) <= margin


class ContestedOnlyReasoner:
    def __init__(self, inner: Reasoner, *, margin: float = DEFAULT_LLM_MARGIN) -> None:
        self.name = inner.name  # the run's reasoner; clear-cut replies name the rules one
        self.margin = margin
        self._inner = inner
        self._rules = RulesReasoner()

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply:
        if is_contested(context, self.margin):
            return self._inner.reason(system, user, context, schema)
        return stood_in(self._rules.reason(system, user, context), Why.CLEAR_CUT)

    def close(self) -> None:
        close_reasoner(self._inner)


def scoped(reasoner: Reasoner, scope: str, margin: float = DEFAULT_LLM_MARGIN) -> Reasoner:
    """`reasoner` asked only for contested decisions under scope 'contested'."""
    if LLMScope(scope) is LLMScope.CONTESTED:
        return ContestedOnlyReasoner(reasoner, margin=margin)
    return reasoner
