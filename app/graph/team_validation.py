"""Validation of a team answer (docs/allocation.md#teams, docs/allocation.md#validation).

Hard rules (Q = 0): a **Team** block naming one known robot per unit, every unit covered,
no robot twice, each member able to cover its unit (skills, room under the cap), and the
team leaving the cap satisfiable for the tasks still to decide (`TeamFacts.check`, the
max-flow completion check) and, on a timed instance, its members free in time: the team's
end, from its last member's arrival, meets the task's deadline and every member's shift
(docs/schedules.md#teams-in-a-run-in-time).
The soft criteria are the eight of app.graph.validation, read for a team: the success is
the team's (the mean over units of the covering member's rate), the workload adds one to
each member, the trade-off rule compares the best-success and the least-loaded team
(app.domain.team_choice), and explanation quality is scored per member as well as for
the whole.
"""

from __future__ import annotations

import math
import re

from app.domain.decision import DecisionContext, Members, TeamFacts, percent
from app.domain.team_choice import TeamRule, describe_team, team_rule
from app.graph.criteria_text import NUMBER_CITED, score_tradeoff, score_workload
from app.graph.parsing import ParsedResponse, count_sentences, mentioned_robots

# Stated success within this of the true S is exact (rounding); beyond the outer bound, 0.
ACCURACY_EXACT = 0.015
ACCURACY_ZERO = 0.15
_MEMBER_FACTS = re.compile(r"\d|rate|success|load|skill|balance", re.IGNORECASE)
_CONFIDENCE_RANK = {"low": 0, "medium": 1, "high": 2}

Result = tuple[float, str]


def accuracy(stated: float | None, true_s: float, what: str) -> Result:
    """The success-rate accuracy criterion: `stated` against the true S of `what`."""
    if stated is None:
        return 0.0, f"no **Expected Success** value (S of {what} is {percent(true_s)})"
    err = abs(stated - true_s)
    if err <= ACCURACY_EXACT:
        return 1.0, ""
    q = max(0.0, 1.0 - (err - ACCURACY_EXACT) / (ACCURACY_ZERO - ACCURACY_EXACT))
    return q, f"stated {percent(stated)} but S of {what} is {percent(true_s)}"


def _needs(facts: TeamFacts) -> str:
    return ", ".join(f"{f} x{facts.count(f)}" for f in facts.features)


def team_members(parsed: ParsedResponse, ctx: DecisionContext) -> tuple[Members | None, str | None]:
    """The team the answer names, in unit order (a feature's members in robot order), or
    why it is hard-invalid."""
    facts, labels = ctx.team, ctx.labels
    assert facts is not None
    if not parsed.team:
        if parsed.decision_text is None:
            return None, "no parseable decision: the answer has no **Team** block"
        return None, (
            f"no **Team** block: this task needs a team ({_needs(facts)}); list one line per "
            "unit, `- <feature>: <robot> — <why>`"
        )
    chosen: dict[str, list[int]] = {}
    for line in parsed.team:
        if line["robot"] is None:
            return None, (
                f"unknown robot '{line['text']}' for {line['feature']} in **Team**; name one "
                f"of: {', '.join(labels)}"
            )
        chosen.setdefault(line["feature"], []).append(line["robot"])
    for f in facts.features:
        got, need = len(chosen.get(f, [])), facts.count(f)
        if got < need:
            return None, (
                f"{need - got} unit(s) of {f} not covered: the team needs {need} robot(s) for "
                f"{f} and the answer names {got}"
            )
        if got > need:
            return None, f"{got} robots named for {f}, which has {need} unit(s); one per unit"
    members = tuple(r for f in facts.features for r in sorted(chosen[f]))
    repeated = sorted({r for r in members if members.count(r) > 1})
    if repeated:
        return None, (
            f"{labels[repeated[0]]} covers two units; a team's members are distinct robots"
        )
    for f, r in zip(facts.units, members, strict=True):
        if facts.rate(f, r) is None:
            if r in ctx.feasible:
                return None, f"{labels[r]} cannot cover {f} (its skills rule it out)"
            if ctx.timing and not ctx.timing[r].allowed and ctx.timing[r].end != math.inf:
                # docs/allocation.md#teams: members free in time; no team starts before any
                # member could, so this member's own miss is the team's.
                o = ctx.timing[r]
                return None, (
                    f"{labels[r]} is not free in time: with it the team could not start before "
                    f"minute {o.start:g}, end before {o.end:g}, and {o.why_not}"
                )
            return None, (
                f"{labels[r]} cannot join this team (it may not take the task, or has no "
                "room left under the workload cap)"
            )
    why = facts.problem(members)
    if why is not None:
        best = facts.best
        hint = f"; allowed, e.g.: {describe_team(facts, labels, best)}" if best else ""
        return None, f"{why}{hint}"
    return members, None


def _explanation(p: ParsedResponse, ctx: DecisionContext, members: Members) -> Result:
    """Half for the **Reasoning** as a whole, half for each member's own sentence."""
    text, labels = p.reasoning or "", ctx.labels
    problems: list[str] = []
    whole = 0.0
    if len(text) >= 60:
        whole += 0.25
    else:
        problems.append("the reasoning is too short to explain anything")
    if 2 <= count_sentences(text) <= 4:
        whole += 0.25
    else:
        problems.append(f"the reasoning has {count_sentences(text)} sentence(s) instead of 2-4")
    if set(members) & mentioned_robots(text, ctx.robot_names, ctx.labels):
        whole += 0.25
    else:
        problems.append("the reasoning names no member of the team")
    if NUMBER_CITED.search(text):
        whole += 0.25
    else:
        problems.append("the reasoning cites no success rates or loads as numbers")
    per: list[float] = []
    for line in p.team:
        reason = line["reason"]
        q = (0.5 if len(reason) >= 15 else 0.0) + (0.5 if _MEMBER_FACTS.search(reason) else 0.0)
        if q < 1.0:
            who = labels[line["robot"]] if line["robot"] is not None else line["text"]
            problems.append(f"the {line['feature']} line for {who} gives no reason with its rate")
        per.append(q)
    members_q = sum(per) / len(per) if per else 0.0
    return 0.5 * whole + 0.5 * members_q, "; ".join(problems)


def _tradeoff(p: ParsedResponse, ctx: DecisionContext, members: Members, rule: TeamRule) -> Result:
    text = p.tradeoff or ""
    others = mentioned_robots(text, ctx.robot_names, ctx.labels) - set(members)
    named_team = re.search(r"\bteam\b", text, re.IGNORECASE) is not None
    return score_tradeoff(
        text,
        success_side="team S or the gap in points",
        compares=bool(others) or rule.best == rule.fewest or named_team,
        no_alternative="it compares no alternative team",
    )


def _workload(p: ParsedResponse, ctx: DecisionContext, members: Members) -> Result:
    after = list(ctx.loads)
    for r in members:
        after[r] += 1
    return score_workload(p.workload_after, after, ctx.labels)


def _mode(ctx: DecisionContext, members: Members, rule: TeamRule) -> Result:
    facts = ctx.team
    assert facts is not None
    if members == rule.choice or members == facts.guided:
        return 1.0, ""
    why = (
        f"the trade-off rule picks the team {describe_team(facts, ctx.labels, rule.choice)} "
        f"({rule.rule.rule_text}; best-success team vs least-loaded team)"
    )
    return (0.5 if rule.index(members) is not None else 0.0), why


def _logic(p: ParsedResponse, ctx: DecisionContext, members: Members, rule: TeamRule) -> Result:
    facts = ctx.team
    assert facts is not None
    q, problems = 0.0, []
    if set(members) & mentioned_robots(p.reasoning or "", ctx.robot_names, ctx.labels):
        q += 0.25
    else:
        problems.append("the reasoning does not discuss the team it chose")
    first = [r for f, r in zip(facts.units, members, strict=True) if f == facts.units[0]]
    if p.robot in first:
        q += 0.25
    else:
        problems.append(f"**Decision** should name the member covering {facts.units[0]}")
    stated, own = p.expected_success, facts.success(members)
    rivals = [facts.success(m) for m in rule.teams]
    if stated is not None and abs(stated - own) <= min(abs(stated - s) for s in rivals) + 1e-9:
        q += 0.5
    else:
        problems.append("the expected success is not the chosen team's")
    return q, "; ".join(problems)


def _confidence(
    p: ParsedResponse, ctx: DecisionContext, members: Members, rule: TeamRule
) -> Result:
    facts = ctx.team
    assert facts is not None
    expected = rule.confidence(members, facts.guided)
    if p.confidence is None:
        return 0.0, f"no **Confidence Level** (High/Medium/Low); {expected} fits this decision"
    distance = abs(_CONFIDENCE_RANK[p.confidence] - _CONFIDENCE_RANK[expected])
    if distance == 0:
        return 1.0, ""
    note = f"stated {p.confidence}, but {expected} fits ({rule.rule.rule_text})"
    return (0.5 if distance == 1 else 0.0), note


def team_criteria(p: ParsedResponse, ctx: DecisionContext, members: Members) -> dict[str, Result]:
    """Seven of the eight criteria (phase consistency reads the same for a team)."""
    facts = ctx.team
    assert facts is not None
    rule = team_rule(ctx)
    return {
        "explanation": _explanation(p, ctx, members),
        "success_accuracy": accuracy(p.expected_success, facts.success(members), "the team"),
        "tradeoff_analysis": _tradeoff(p, ctx, members, rule),
        "workload_awareness": _workload(p, ctx, members),
        "mode_compliance": _mode(ctx, members, rule),
        "logical_consistency": _logic(p, ctx, members, rule),
        "confidence_justification": _confidence(p, ctx, members, rule),
    }
