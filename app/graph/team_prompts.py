"""The prompt of a team task (docs/allocation.md#teams): per unit, the robots that may cover it
with their rate for its feature; per robot its load and deviation; the two candidate teams
the trade-off rule compares; and the team reply format. Kept as compact as the one-robot
prompt: one line per robot, one per feature, two for the candidates.
"""

from __future__ import annotations

import math

from app.domain.decision import DecisionContext, TeamFacts, percent
from app.domain.modes import tradeoff_threshold
from app.domain.scheduling.progress import TimeOption
from app.domain.team_choice import by_rate, describe_team, team_summary
from app.domain.tradeoff import CLEAR_MARGIN, DECISIVE_GAP, NEGLIGIBLE_GAP

TEAM_FORMAT = """Reply in exactly this format:
**Decision**: <the robot covering the first unit>
**Team**:
- <feature>: <robot label> — <one sentence: why this robot, citing its rate>
(one line per unit, in the order of the units above)
**Expected Success**: <the team's S: mean over units of the member's rate, e.g. 72.5%>
**Reasoning**: <2-4 sentences citing the team's S, the members' loads and the phase>
**Workload After Assignment**: <Label: count, for every robot; +1 for each member>
**Confidence Level**: <High|Medium|Low>
**Trade-Off Summary**: <best team vs least-loaded team, gap in points, rule applied>"""


def _facts_of(ctx: DecisionContext) -> TeamFacts:
    assert ctx.team is not None
    return ctx.team


def team_facts_text(ctx: DecisionContext) -> str:
    facts, labels = _facts_of(ctx), ctx.labels
    need = ", ".join(f"{f} x{facts.count(f)}" for f in facts.features)
    number = ctx.task_index if ctx.allocated is None else ctx.allocated
    task_type = f" ({ctx.task_type})" if ctx.task_type else ""
    timed = bool(ctx.timing) and facts.timing is not None
    rows = [
        f"- {labels[r]} [{ctx.robot_names[r]}]: load {ctx.loads[r]} "
        f"(dev {ctx.loads[r] - ctx.target:+.1f})"
        + ("" if r in ctx.feasible else ", NOT allowed")
        + (_robot_time(ctx.timing[r]) if timed else "")
        for r in range(len(labels))
    ]
    units = []
    for k, f in enumerate(facts.features):
        able = by_rate(facts.rates[k], range(len(labels)))
        who = ", ".join(f"{labels[r]} {percent(facts.rates[k][r] or 0.0)}" for r in able)
        units.append(f"- {f} x{facts.count(f)}: {who or 'no allowed robot'}")
    cap = (
        "no workload cap"
        if ctx.load_bounds is None
        else f"cap: final loads in [{ctx.load_bounds[0]}, {ctx.load_bounds[1]}]"
    )
    candidates = []
    if facts.best is not None and facts.fewest is not None:
        candidates = [
            "Teams the cap allows (S = mean over units of the member's rate; loads = the "
            "members' tasks so far):",
            f"- best: {team_summary(facts, labels, ctx.loads, facts.best)}"
            + (_team_time(ctx, facts.best) if timed else ""),
            f"- least-loaded: {team_summary(facts, labels, ctx.loads, facts.fewest)}"
            + (_team_time(ctx, facts.fewest) if timed else ""),
        ]
    return "\n".join(
        [
            f"Task {number + 1}/{ctx.total_tasks}: {ctx.task_name}{task_type}; "
            f"features: {', '.join(ctx.features)}",
            f"Team task: {need}; {len(facts.units)} distinct robots at once, one per unit.",
            "Robots (load = tasks so far; a team task adds one to each member's load"
            + ("; minutes: free, travel, own start-end):" if timed else "):"),
            *rows,
            "Units (robots that may cover each, with their rate for its feature):",
            *units,
            *candidates,
            f"Target load W = {ctx.target:.1f} (units per robot); allocated {number}/"
            f"{ctx.total_tasks} tasks; {cap}.",
            *team_time_facts(ctx),
        ]
    )


def _robot_time(o: TimeOption) -> str:
    if o.end == math.inf:
        return f"; {o.why_not}"
    why = "" if o.allowed else f" ({o.why_not})"
    return f"; free {o.free:g}, travel {o.travel:g}, {o.start:g}-{o.end:g}{why}"


def _team_time(ctx: DecisionContext, members: tuple[int, ...]) -> str:
    assert ctx.team is not None and ctx.team.timing is not None
    o = ctx.team.timing(members)
    slack = "" if ctx.deadline is None else f", slack {o.slack:g}"
    return f", in time {o.start:g}-{o.end:g}{slack}"


def team_time_facts(ctx: DecisionContext) -> list[str]:
    """docs/schedules.md#teams-in-a-run-in-time, a timed team task (each robot's own time is on
    its row, each candidate team's start and end on its line): the task's zone, release and
    deadline, and the rule "members free in time"."""
    facts = _facts_of(ctx)
    if not ctx.timing or facts.timing is None:
        return []
    where = f"zone {ctx.zone}, " if ctx.zone is not None else ""
    deadline = "no deadline" if ctx.deadline is None else f"deadline {ctx.deadline:g}"
    return [
        f"In time ({where}release {ctx.release:g}, {deadline}): a team starts at its last "
        "member's arrival, ends with all; missing the deadline or a shift: not allowed.",
        *(["Links (the times above honour them): " + "; ".join(ctx.links)] if ctx.links else []),
        "In the Trade-Off Summary, say how many minutes after the earliest end yours ends.",
    ]


def team_guidance(ctx: DecisionContext) -> list[str]:
    """The decision framework for teams, and the optimizer's team when the run is guided."""
    return team_framework(ctx) + team_steering(ctx)


def team_framework(ctx: DecisionContext) -> list[str]:
    """The decision framework for teams (the same for every task of a mode and phase)."""
    threshold = tradeoff_threshold(ctx.mode, ctx.phase)
    return [
        "Decision framework for teams: compare the best and the least-loaded team above; gap = "
        f"S(best) - S(least-loaded) in points. Gap > {DECISIVE_GAP:g}: best. Gap < "
        f"{NEGLIGIBLE_GAP:g}: least-loaded. Otherwise best if gap > {threshold:g}, else "
        "least-loaded. Another team must keep every member allowed and the cap satisfiable.",
        f"Confidence: High if the gap is {CLEAR_MARGIN:g}+ points from the deciding cut-off, "
        "Medium if closer, Low if you depart from the rule.",
    ]


def team_steering(ctx: DecisionContext) -> list[str]:
    """The optimizer's team, when the run is guided."""
    facts = _facts_of(ctx)
    if facts.guided is None:
        return []
    return [
        f"Optimizer guidance: the team {describe_team(facts, ctx.labels, facts.guided)} lies "
        "on the optimal completion of the queue; follow it, or explain why you depart."
    ]


def team_step_template(ctx: DecisionContext) -> str:
    """Tier 3 for a team task: fill in the chosen team line by line."""
    facts = _facts_of(ctx)
    threshold = tradeoff_threshold(ctx.mode, ctx.phase)
    lines = "\n".join(f"- {f}: <robot> — <why, with its rate>" for f in facts.units)
    return f"""Work through these steps, then fill in the template. Replace every <...>.
1. Take the best and the least-loaded team listed above; gap = S(best) - S(least-loaded).
2. If gap > {DECISIVE_GAP:g} choose best; if gap < {NEGLIGIBLE_GAP:g} choose least-loaded; \
otherwise best if gap > {threshold:g}, else least-loaded.
3. Workload after: add 1 to each member of the chosen team.

**Decision**: <the member covering {facts.units[0]}>
**Team**:
{lines}
**Expected Success**: <the chosen team's S>%
**Reasoning**: The team <members> has S <S>% versus <S>% for the other team. The gap is <gap> \
points, so rule <step 2 clause> applies in the {ctx.phase.value} phase of {ctx.mode.value} mode.
**Workload After Assignment**: <Label: count, for every robot>
**Confidence Level**: <High|Medium>
**Trade-Off Summary**: best team <S>% vs least-loaded team <S>% (<loads> tasks): gap <gap> \
points, so <best|least-loaded> takes the task."""
