"""The embedded default reasoner: the trade-off rule, written out in the required format.

Deterministic, offline, zero tokens. Its answers say they are rule-based; it reads the
true DecisionContext rather than the prompt, so it is also the graph's fallback.
"""

from __future__ import annotations

from app.domain.decision import DecisionContext, Members, percent
from app.domain.team_choice import TeamRule, describe_team, team_load, team_rule, team_summary
from app.domain.tradeoff import TradeOff, expected_confidence, rule_for
from app.reasoners.base import ReasonerReply
from app.reasoners.structured import ReplySchema


def choose(ctx: DecisionContext) -> tuple[int, TradeOff]:
    """The rules reasoner's robot: optimizer guidance when given and allowed, else the rule."""
    rule = rule_for(ctx)
    if ctx.guided_robot is not None and ctx.guided_robot in ctx.feasible:
        return ctx.guided_robot, rule
    return rule.choice, rule


def choose_team(ctx: DecisionContext) -> tuple[Members, TeamRule]:
    """The rules reasoner's team (docs/allocation.md#teams): the optimizer's team when given
    and allowed, else the trade-off rule between the best-success and the least-loaded team
    the cap allows. Also the graph's fallback team."""
    facts = ctx.team
    assert facts is not None
    rule = team_rule(ctx)
    if facts.guided is not None and facts.problem(facts.guided) is None:
        return facts.guided, rule
    return rule.choice, rule


def compose_team_answer(
    ctx: DecisionContext,
    members: Members | None = None,
    why: str = "Rule-based choice (the trade-off rule, not a language model)",
) -> str:
    """The answer in the team format: **Team** one line per unit, with its member's reason
    (`members`: another team than the rule's, the graph's fallback in time, and `why` it)."""
    facts = ctx.team
    assert facts is not None
    chosen, rule = choose_team(ctx)
    members = chosen if members is None else members
    names, loads = ctx.labels, ctx.loads
    s = facts.success(members)
    lines = [
        f"- {f}: {names[r]} — covers {f} at {percent(facts.rate(f, r) or 0.0)} with {loads[r]} "
        "tasks so far."
        for f, r in zip(facts.units, members, strict=True)
    ]
    guided = facts.guided is not None and members == facts.guided
    when = ""  # untimed: the answer is exactly what it always was
    if facts.timing is not None:  # docs/allocation.md#teams: when the last member can begin
        o = facts.timing(members)
        when = f"; the team would start at minute {o.start:g} and end at {o.end:g}"
    sentences = [
        f"{why}: the team "
        f"{describe_team(facts, names, members)} has success {percent(s)} on {ctx.task_name}, "
        f"the mean over its {len(facts.units)} units.",
        f"The best team the cap allows is {team_summary(facts, names, loads, rule.best)} and the "
        f"least-loaded is {team_summary(facts, names, loads, rule.fewest)}; "
        f"{rule.rule.rule_text.replace('robot', 'team')}.",
        f"This is the {ctx.phase.value} phase of {ctx.mode.value} mode, with a threshold of "
        f"{rule.rule.threshold:g} points{when}.",
    ]
    if guided:
        sentences.append("The optimizer's guidance names this team, and this choice follows it.")
    after = list(loads)
    for r in members:
        after[r] += 1
    tradeoff = (
        f"Best team {describe_team(facts, names, rule.best)} {percent(facts.success(rule.best))} "
        f"vs least-loaded team {describe_team(facts, names, rule.fewest)} "
        f"({team_load(loads, rule.fewest)} tasks between them): "
        f"{rule.rule.rule_text.replace('robot', 'team')}."
    )
    return "\n".join(
        [
            f"**Decision**: {names[members[0]]}",
            "**Team**:",
            *lines,
            f"**Expected Success**: {percent(s)}",
            f"**Reasoning**: {' '.join(sentences)}",
            "**Workload After Assignment**: "
            + ", ".join(f"{names[r]}: {after[r]}" for r in range(len(after))),
            f"**Confidence Level**: {rule.confidence(members, facts.guided).capitalize()}",
            f"**Trade-Off Summary**: {tradeoff}",
        ]
    )


def compose_answer(ctx: DecisionContext) -> str:
    if ctx.team is not None:
        return compose_team_answer(ctx)
    choice, rule = choose(ctx)
    names, s, loads = ctx.labels, ctx.success, ctx.loads
    others = sorted((r for r in range(len(s)) if r != choice), key=lambda r: (-s[r], r))
    alternatives = ", ".join(
        f"{names[r]} {percent(s[r])} with {loads[r]} tasks" for r in others[:2]
    )
    features = ", ".join(ctx.features)
    sentences = [
        f"Rule-based choice (the trade-off rule, not a language model): {names[choice]} has "
        f"success {percent(s[choice])} on {ctx.task_name} ({features}) with {loads[choice]} "
        f"tasks so far" + (f", against {alternatives}." if alternatives else "."),
        f"Among the robots the cap allows, the best is {names[rule.best]} at "
        f"{percent(s[rule.best])} and the least loaded is {names[rule.fewest]} with "
        f"{loads[rule.fewest]} tasks (target {ctx.target:.1f}); {rule.rule_text}.",
        f"This is the {ctx.phase.value} phase of {ctx.mode.value} mode, weighting success to "
        f"balance {ctx.weights}, with a threshold of {rule.threshold:g} points.",
    ]
    guided = ctx.guided_robot is not None and choice == ctx.guided_robot
    if guided:
        sentences.append(
            f"The optimizer's guidance names {names[choice]}, and this choice follows it"
            + ("." if choice == rule.choice else f" instead of the rule's {names[rule.choice]}.")
        )
    after = list(loads)
    after[choice] += 1
    confidence = expected_confidence(rule, choice, ctx.guided_robot if guided else None)
    runner_up = f"; runner-up {names[others[0]]} at {percent(s[others[0]])}" if others else ""
    tradeoff = (
        f"Best {names[rule.best]} {percent(s[rule.best])} vs least-loaded {names[rule.fewest]} "
        f"({loads[rule.fewest]} tasks): {rule.rule_text}; {names[choice]} takes the task"
        f"{runner_up}."
    )
    analysis = "; ".join(
        f"{names[r]} {percent(s[r])}, load {loads[r]}"
        + ("" if r in ctx.feasible else " (cap: not allowed)")
        for r in range(len(s))
    )
    return "\n".join(
        [
            f"**Decision**: {names[choice]}",
            f"**Expected Success**: {percent(s[choice])}",
            f"**Reasoning**: {' '.join(sentences)}",
            "**Workload After Assignment**: "
            + ", ".join(f"{names[r]}: {after[r]}" for r in range(len(after))),
            f"**Confidence Level**: {confidence.capitalize()}",
            f"**Trade-Off Summary**: {tradeoff}",
            f"**Robot Analysis**: {analysis}",
        ]
    )


class RulesReasoner:
    name = "rules"

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply:
        return ReasonerReply(text=compose_answer(context))
