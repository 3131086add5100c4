"""What a supervisor sees of a team decision (docs/reviews.md#reviews-of-team-decisions): the
proposed team and, as alternatives, the rules reasoner's candidate teams (every team of
distinct robots that may join, `app.domain.team_choice.candidate_teams`), each with its success,
whether it keeps the workload cap satisfiable and its regret if chosen.

A fleet can have thousands of candidate teams; the review lists the MAX_LISTED best by success
(ties: fewer tasks between the members), and always the proposal, the trade-off rule's two
candidates and the optimizer's team. A team not listed may still be sent as an override: the
reviews service checks it against the run's problem.
"""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from app.domain.decision import DecisionContext, Members, TeamFacts
from app.domain.team_choice import candidate_teams, team_load

MAX_LISTED = 12


def team_json(units: Sequence[str], names: Sequence[str], members: Members) -> list[dict[str, str]]:
    return [{"robot": names[r], "feature": f} for f, r in zip(units, members, strict=True)]


def members_of(team: Sequence[tuple[str, str]], names: Sequence[str]) -> Members:
    """A resolution's team (names, unit order) as robot indexes."""
    index = {name: r for r, name in enumerate(names)}
    return tuple(index[name] for name, _ in team)


def canonical(units: Sequence[str], members: Members) -> Members:
    """One form per team: the members of one feature in robot order (the candidates' form), so
    a proposal that lists two `heavy` members the other way round is the same team."""
    out: list[int] = []
    for feature in dict.fromkeys(units):
        out += sorted(r for f, r in zip(units, members, strict=True) if f == feature)
    return tuple(out)


def team_units(facts: TeamFacts, names: Sequence[str]) -> list[dict[str, Any]]:
    """Per feature of the team: how many units need it and the robots that may cover one now
    (eligible, with room under the cap): what an override may choose from."""
    return [
        {
            "feature": f,
            "count": facts.count(f),
            "robots": [names[r] for r, rate in enumerate(rates) if rate is not None],
        }
        for f, rates in zip(facts.features, facts.rates, strict=True)
    ]


def team_alternatives(
    dctx: DecisionContext, proposed: Members, cost: Callable[[Members], float | None]
) -> list[dict[str, Any]]:
    """The listed candidate teams, best success first (the proposal in its own unit order)."""
    facts = dctx.team
    if facts is None:
        return []
    units, loads, names = facts.units, dctx.loads, dctx.robot_names
    ranked = sorted(
        candidate_teams(facts, dctx.feasible),
        key=lambda m: (-facts.success(m), team_load(loads, m), m),
    )
    always = [canonical(units, m) for m in (proposed, facts.best, facts.fewest, facts.guided) if m]
    keep = set(always) | set(ranked[:MAX_LISTED])
    listed = [m for m in ranked if m in keep]
    listed += [m for m in dict.fromkeys(always) if m not in set(ranked)]  # e.g. a guided team
    mine = canonical(units, proposed)
    out = []
    for m in listed:
        members = proposed if m == mine else m
        feasible = facts.problem(members) is None
        regret = cost(members) if feasible else None
        out.append(
            {
                "robot": names[members[0]],
                "team": team_json(units, names, members),
                "success": facts.success(members),
                "load": team_load(loads, members),
                "cap_feasible": feasible,
                "regret_if_chosen": None if regret is None else round(max(0.0, regret), 6),
            }
        )
    return out
