"""The reply-format parts of the prompts when a run asks for structured replies
(docs/reasoners.md#structured-replies): the JSON object to fill in instead of the paper's
markdown sections, for one robot and for a team, and the tier-2 example and tier-3 template
in the same shape. The facts, guidance and feedback of each tier are the markdown prompts'
own (app.graph.prompts); only the part that says how to answer differs.
"""

from __future__ import annotations

import json

from app.domain.decision import DecisionContext
from app.domain.modes import tradeoff_threshold
from app.domain.tradeoff import CLEAR_MARGIN, DECISIVE_GAP, NEGLIGIBLE_GAP
from app.graph.reply_schema import (
    MEMBER_REASON_CHARS,
    REASONING_CHARS,
    TRADEOFF_CHARS,
    allowed_labels,
    robot_names,
)

SYSTEM_SUFFIX = "Reply with the required JSON object and nothing else."


def _loads(ctx: DecisionContext, value: str) -> str:
    return "{" + ", ".join(f'"{name}": {value}' for name in robot_names(ctx)) + "}"


def json_format(ctx: DecisionContext) -> str:
    """The object, each field with what it must hold: the same for every decision of a run
    (the robots allowed now are listed with the task's facts)."""
    if ctx.team is not None:
        return _team_format(ctx)
    return f"""Reply with one JSON object and nothing else:
{{"decision": "<the label of one robot allowed now>",
 "expected_success": <S of the chosen robot in percent, e.g. 70.0>,
 "reasoning": "<2-4 sentences citing S values, loads and the phase; at most \
{REASONING_CHARS} characters>",
 "workload_after": {_loads(ctx, "<count>")} (every robot's load after this task),
 "confidence": "<High|Medium|Low>",
 "tradeoff": "<best vs least-loaded robot, gap in points, rule applied; at most \
{TRADEOFF_CHARS} characters>"}}"""


def _team_format(ctx: DecisionContext) -> str:
    return f"""Reply with one JSON object and nothing else:
{{"decision": "<the robot covering the first unit>",
 "team": [{{"feature": "<feature>", "robot": "<the label of a robot allowed now>", \
"reason": "<one sentence: why this robot, citing its rate; at most {MEMBER_REASON_CHARS} \
characters>"}}, ...] (one entry per unit, in the order of the task's units),
 "expected_success": <the team's S in percent: mean over units of the member's rate, e.g. 72.5>,
 "reasoning": "<2-4 sentences citing the team's S, the members' loads and the phase>",
 "workload_after": {_loads(ctx, "<count>")} (+1 for each member),
 "confidence": "<High|Medium|Low>",
 "tradeoff": "<best team vs least-loaded team, gap in points, rule applied>"}}"""


WORKED_EXAMPLE = (
    "Worked example (different data): robots A (S 90%, load 5), B (S 70%, load 3), C \
(S 60%, load 4); middle phase, threshold 13. best = A, fewest = B, gap = 20 points: not > 25, \
not < 5, and 20 > 13, so choose A; 20 is 7 points from 13, so confidence High.\n"
    + json.dumps(
        {
            "decision": "A",
            "expected_success": 90.0,
            "reasoning": "A has the highest success at 90.0% against 70.0% for B, the least-loaded "
            "robot with 3 tasks. The gap of 20 points exceeds the middle-phase threshold of 13, so "
            "success wins over balance.",
            "workload_after": {"A": 6, "B": 3, "C": 4},
            "confidence": "High",
            "tradeoff": "best A 90.0% vs least-loaded B 70.0% (3 tasks): gap 20 > 13 points, so A "
            "takes the task.",
        }
    )
)


def step_template(ctx: DecisionContext) -> str:
    """Tier 3 for one robot: the steps of the rule, then the object with blanks."""
    labels = ctx.labels
    threshold = tradeoff_threshold(ctx.mode, ctx.phase)
    names = robot_names(ctx)
    counts = (
        "{"
        + ", ".join(
            f'"{names[r]}": <{ctx.loads[r]} or {ctx.loads[r] + 1}>' for r in range(len(labels))
        )
        + "}"
    )
    return f"""Work through these steps, then fill in the object. Replace every <...>.
1. Allowed robots: {", ".join(allowed_labels(ctx))}.
2. best = the allowed robot with the highest S; fewest = the allowed robot with the lowest load.
3. gap = S(best) - S(fewest) in points.
4. If gap > {DECISIVE_GAP:g} choose best; if gap < {NEGLIGIBLE_GAP:g} choose fewest; otherwise \
choose best if gap > {threshold:g}, else fewest.
5. Workload after: add 1 to the chosen robot only.
6. Confidence: High if the gap is {CLEAR_MARGIN:g}+ points from the cut-off used in step 4, else \
Medium.

{{"decision": "<robot from step 4>", "expected_success": <its S from the table>, \
"reasoning": "<robot> has S <S>% versus <other robot> at <S>%. The gap is <gap> points, so rule \
<step 4 clause> applies in the {ctx.phase.value} phase of {ctx.mode.value} mode.", \
"workload_after": {counts}, "confidence": "<High|Medium>", "tradeoff": "best <best> <S>% vs \
least-loaded <fewest> (<load> tasks): gap <gap> points, so <robot> takes the task."}}"""


def team_step_template(ctx: DecisionContext) -> str:
    """Tier 3 for a team task: the steps of the team rule, then the object with blanks."""
    facts = ctx.team
    assert facts is not None
    threshold = tradeoff_threshold(ctx.mode, ctx.phase)
    members = ", ".join(
        f'{{"feature": "{f}", "robot": "<robot>", "reason": "<why, with its rate>"}}'
        for f in facts.units
    )
    return f"""Work through these steps, then fill in the object. Replace every <...>.
1. Take the best and the least-loaded team listed above; gap = S(best) - S(least-loaded).
2. If gap > {DECISIVE_GAP:g} choose best; if gap < {NEGLIGIBLE_GAP:g} choose least-loaded; \
otherwise best if gap > {threshold:g}, else least-loaded.
3. Workload after: add 1 to each member of the chosen team.

{{"decision": "<the member covering {facts.units[0]}>", "team": [{members}], \
"expected_success": <the chosen team's S>, "reasoning": "The team <members> has S <S>% versus \
<S>% for the other team. The gap is <gap> points, so rule <step 2 clause> applies in the \
{ctx.phase.value} phase of {ctx.mode.value} mode.", "workload_after": \
{_loads(ctx, "<count>")}, "confidence": "<High|Medium>", "tradeoff": "best team <S>% vs \
least-loaded team <S>% (<loads> tasks): gap <gap> points, so <best|least-loaded> takes the \
task."}}"""
