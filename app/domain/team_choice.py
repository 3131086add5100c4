"""Choosing a team for one decision of the LTAA graph (docs/allocation.md#teams).

The trade-off rule compares two candidates, as for one robot: `best`, the team with the
highest success the cap allows, and `fewest`, the allowed team whose members carry the
fewest tasks between them (ties: the higher success). The gap is S(best) - S(fewest) in
points and the rule's thresholds apply unchanged (app.domain.tradeoff), so the rules
reasoner, the mode-compliance criterion and the fallback agree on teams as they do on
robots. Teams are enumerated per feature from the robots that may cover it; a fleet so
large that a task has more than MAX_TEAMS teams keeps, per feature, only its best-rated
robots (enough for the count and a few to spare).
"""

from __future__ import annotations

import itertools
import math
from collections.abc import Callable, Iterable, Iterator, Sequence
from dataclasses import dataclass

from app.domain.decision import DecisionContext, Members, TeamFacts, percent
from app.domain.tradeoff import TradeOff, apply_rule, expected_confidence

MAX_TEAMS = 20_000
_SPARE = 3  # robots kept per feature beyond its count when the teams are too many


def by_rate(rates: Sequence[float | None], robots: Iterable[int]) -> list[int]:
    """The robots that may cover a feature (rate not None), the best-rated first."""

    def key(r: int) -> tuple[float, int]:
        return (-(rates[r] or 0.0), r)

    return sorted((r for r in robots if rates[r] is not None), key=key)


def _coverers(facts: TeamFacts, allowed: Sequence[int]) -> list[list[int]]:
    out = [by_rate(rates, allowed) for rates in facts.rates]
    pairs = list(zip(out, facts.features, strict=True))
    total = math.prod(math.comb(len(a), facts.count(f)) for a, f in pairs)
    if total > MAX_TEAMS:
        out = [a[: facts.count(f) + _SPARE] for a, f in pairs]
    return [sorted(a) for a in out]


def candidate_teams(facts: TeamFacts, allowed: Sequence[int]) -> list[Members]:
    """Every team of distinct robots from `allowed` covering the units, in unit order (the
    members of one feature in robot order)."""
    coverers = _coverers(facts, allowed)
    features = facts.features

    def teams(k: int, used: frozenset[int]) -> Iterator[Members]:
        if k == len(features):
            yield ()
            return
        free = [r for r in coverers[k] if r not in used]
        for group in itertools.combinations(free, facts.count(features[k])):
            for rest in teams(k + 1, used | set(group)):
                yield group + rest

    return list(teams(0, frozenset()))


def team_load(loads: Sequence[int], members: Members) -> int:
    return sum(loads[r] for r in members)


def best_and_fewest(
    facts: TeamFacts,
    loads: Sequence[int],
    allowed: Sequence[int],
    check: Callable[[Members], str | None] | None,
) -> tuple[Members | None, Members | None]:
    """The best-success and the least-loaded team that pass `check` (None: none passes)."""
    teams = candidate_teams(facts, allowed)
    s = {m: facts.success(m) for m in teams}
    ok: dict[Members, bool] = {}

    def passes(m: Members) -> bool:
        if m not in ok:
            ok[m] = check is None or check(m) is None
        return ok[m]

    by_success = sorted(teams, key=lambda m: (-s[m], team_load(loads, m), m))
    best = next((m for m in by_success if passes(m)), None)
    by_load = sorted(teams, key=lambda m: (team_load(loads, m), -s[m], m))
    fewest = next((m for m in by_load if passes(m)), None)
    return best, fewest


@dataclass(frozen=True)
class TeamRule:
    """The trade-off rule on the two candidate teams: `rule.best` / `rule.fewest` / choice
    are 0 (the best-success team) or 1 (the least-loaded team)."""

    teams: tuple[Members, Members]
    rule: TradeOff

    @property
    def best(self) -> Members:
        return self.teams[self.rule.best]

    @property
    def fewest(self) -> Members:
        return self.teams[self.rule.fewest]

    @property
    def choice(self) -> Members:
        return self.teams[self.rule.choice]

    def index(self, members: Members | None) -> int | None:
        """0 or 1 for a candidate (the best-success one first), None for another team."""
        if members is None:
            return None
        if members == self.teams[0]:
            return 0
        return 1 if members == self.teams[1] else None

    def confidence(self, members: Members, guided: Members | None) -> str:
        """The confidence a well-justified answer states for `members`."""
        index = self.index(members)
        followed = guided is not None and members == guided
        if index is None:
            return "medium" if followed else "low"
        return expected_confidence(self.rule, index, index if followed else None)


def team_rule(ctx: DecisionContext) -> TeamRule:
    """The rule on ctx's candidate teams (the context carries them: app.graph.context)."""
    facts = ctx.team
    if facts is None or facts.best is None or facts.fewest is None:
        raise ValueError("no team of distinct eligible robots keeps the workload cap satisfiable")
    teams = (facts.best, facts.fewest)
    rule = apply_rule(
        [facts.success(m) for m in teams],
        [team_load(ctx.loads, m) for m in teams],
        [0, 1],
        ctx.mode,
        ctx.phase,
    )
    return TeamRule(teams, rule)


def describe_team(facts: TeamFacts, labels: Sequence[str], members: Members) -> str:
    """`heavy: Heavy Robot, Medium Robot; careful: Light Robot` (prompts and answers)."""
    parts = []
    for feature in facts.features:
        names = [labels[r] for f, r in zip(facts.units, members, strict=True) if f == feature]
        parts.append(f"{feature}: {', '.join(names)}")
    return "; ".join(parts)


def team_summary(facts: TeamFacts, labels: Sequence[str], loads: Sequence[int], m: Members) -> str:
    return (
        f"{describe_team(facts, labels, m)} (S {percent(facts.success(m))}, "
        f"loads {team_load(loads, m)})"
    )
