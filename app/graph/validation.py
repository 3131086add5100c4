"""The eight validation criteria (paper weights) scored against the TRUE decision context.

Every q_i is a deterministic function of the parsed answer and the context, so the same
answer always gets the same Q (a resumed run re-validates to the same verdict).
"""

from __future__ import annotations

import re
from dataclasses import dataclass, field

from app.domain.decision import DecisionContext
from app.domain.tradeoff import TradeOff, expected_confidence, rule_for
from app.graph.criteria_text import NUMBER_CITED, score_tradeoff, score_workload
from app.graph.parsing import ParsedResponse, count_sentences, mentioned_robots
from app.graph.reply_reading import read_reply
from app.graph.team_validation import (
    ACCURACY_EXACT as ACCURACY_EXACT,  # re-exported: tests and tools read them here
)
from app.graph.team_validation import (
    ACCURACY_ZERO as ACCURACY_ZERO,
)
from app.graph.team_validation import (
    accuracy,
    team_criteria,
    team_members,
)

DEFAULT_QUALITY_THRESHOLD = 0.6

WEIGHTS: dict[str, float] = {
    "explanation": 0.20,
    "success_accuracy": 0.20,
    "tradeoff_analysis": 0.15,
    "workload_awareness": 0.15,
    "mode_compliance": 0.10,
    "phase_consistency": 0.10,
    "logical_consistency": 0.05,
    "confidence_justification": 0.05,
}

CRITERION_TITLES: dict[str, str] = {
    "explanation": "explanation quality",
    "success_accuracy": "success-rate accuracy",
    "tradeoff_analysis": "trade-off analysis",
    "workload_awareness": "workload awareness",
    "mode_compliance": "mode compliance",
    "phase_consistency": "phase consistency",
    "logical_consistency": "logical consistency",
    "confidence_justification": "confidence justification",
}

_CONFIDENCE_RANK = {"low": 0, "medium": 1, "high": 2}
_PHASE_WORD = re.compile(r"\b(early|middle|mid|late)\b", re.IGNORECASE)


@dataclass
class Validation:
    robot: int | None
    scores: dict[str, float]
    notes: dict[str, str]  # why a criterion lost points, in words the feedback can reuse
    quality: float
    accepted: bool
    hard_invalid: str | None = None
    parsed: ParsedResponse = field(default_factory=ParsedResponse)
    # A team task (docs/allocation.md#teams): the members in unit order; `robot` is the first.
    team: tuple[int, ...] | None = None


def hard_invalid_reason(parsed: ParsedResponse, ctx: DecisionContext) -> str | None:
    labels = ctx.labels
    if parsed.decision_text is None:
        return "no parseable decision: the answer has no **Decision** line"
    if parsed.robot is None:
        return (
            f"unknown robot '{parsed.decision_text}' in **Decision**; name one of: "
            f"{', '.join(labels)}"
        )
    if parsed.robot not in ctx.feasible:
        allowed = ", ".join(labels[r] for r in ctx.feasible)
        if ctx.eligible and not ctx.eligible[parsed.robot]:
            # docs/allocation.md#teams: eligibility is a hard rule, like the cap.
            return (
                f"{labels[parsed.robot]} cannot take this task (its skills or the task's "
                f"duration map rule it out); allowed now: {allowed}"
            )
        if ctx.timing and not ctx.timing[parsed.robot].allowed:
            # docs/schedules.md#validation-in-time: a choice that misses the deadline or breaks a
            # shift is hard-invalid.
            why = ctx.timing[parsed.robot].why_not
            return f"{labels[parsed.robot]} {why}; allowed now: {allowed}"
        return (
            f"{labels[parsed.robot]} would make the workload cap infeasible; allowed now: {allowed}"
        )
    return None


def _explanation(p: ParsedResponse, ctx: DecisionContext, choice: int) -> tuple[float, str]:
    text = p.reasoning or ""
    if not text.strip():
        return 0.0, "the **Reasoning** section is missing"
    problems: list[str] = []
    q = 0.0
    if len(text) >= 60:
        q += 0.25
    else:
        problems.append("it is too short to explain anything")
    n = count_sentences(text)
    if 2 <= n <= 4:
        q += 0.25
    else:
        q += 0.1 if n in (1, 5, 6) else 0.0
        problems.append(f"it has {n} sentence(s) instead of 2-4")
    if choice in mentioned_robots(text, ctx.robot_names, ctx.labels):
        q += 0.25
    else:
        problems.append("it does not name the chosen robot")
    if NUMBER_CITED.search(text):
        q += 0.25
    else:
        problems.append("it cites no success rates or loads as numbers")
    return q, "; ".join(problems)


def _accuracy(p: ParsedResponse, ctx: DecisionContext, choice: int) -> tuple[float, str]:
    return accuracy(p.expected_success, ctx.success[choice], ctx.labels[choice])


def _tradeoff_analysis(p: ParsedResponse, ctx: DecisionContext, choice: int) -> tuple[float, str]:
    text = p.tradeoff or ""
    others = mentioned_robots(text, ctx.robot_names, ctx.labels) - {choice}
    return score_tradeoff(
        text,
        success_side="S or the gap in points",
        compares=bool(others) or len(ctx.feasible) <= 1,
        no_alternative="it names no alternative robot to compare against",
    )


def _workload(p: ParsedResponse, ctx: DecisionContext, choice: int) -> tuple[float, str]:
    after = list(ctx.loads)
    after[choice] += 1
    return score_workload(p.workload_after, after, ctx.labels)


def _mode(ctx: DecisionContext, choice: int, rule: TradeOff) -> tuple[float, str]:
    if choice == rule.choice or choice == ctx.guided_robot:
        return 1.0, ""
    labels = ctx.labels
    why = (
        f"the trade-off rule picks {labels[rule.choice]} ({rule.rule_text}; best "
        f"{labels[rule.best]}, least-loaded {labels[rule.fewest]})"
    )
    if choice in (rule.best, rule.fewest):
        return 0.5, why
    return 0.0, why


def _phase(p: ParsedResponse, ctx: DecisionContext) -> tuple[float, str]:
    text = " ".join(x for x in (p.reasoning, p.tradeoff, p.robot_analysis) if x)
    named = {"middle" if w.lower() == "mid" else w.lower() for w in _PHASE_WORD.findall(text)}
    true = ctx.phase.value
    if named == {true}:
        return 1.0, ""
    if true in named:
        return 0.5, f"it names other phases besides the true one ({true})"
    if not named:
        return 0.2, f"it does not name the phase ({true})"
    return 0.0, f"it names the {'/'.join(sorted(named))} phase but this is the {true} phase"


def _logic(p: ParsedResponse, ctx: DecisionContext, choice: int) -> tuple[float, str]:
    q, problems = 0.0, []
    if choice in mentioned_robots(p.reasoning or "", ctx.robot_names, ctx.labels):
        q += 0.5
    else:
        problems.append("the reasoning does not discuss the robot it chose")
    stated = p.expected_success
    if (
        stated is not None
        and abs(stated - ctx.success[choice]) <= min(abs(stated - s) for s in ctx.success) + 1e-9
    ):
        q += 0.5
    else:
        problems.append("the expected success does not belong to the chosen robot")
    return q, "; ".join(problems)


def _confidence(
    p: ParsedResponse, ctx: DecisionContext, choice: int, rule: TradeOff
) -> tuple[float, str]:
    expected = expected_confidence(rule, choice, ctx.guided_robot)
    if p.confidence is None:
        return 0.0, f"no **Confidence Level** (High/Medium/Low); {expected} fits this decision"
    distance = abs(_CONFIDENCE_RANK[p.confidence] - _CONFIDENCE_RANK[expected])
    if distance == 0:
        return 1.0, ""
    note = f"stated {p.confidence}, but {expected} fits ({rule.rule_text})"
    return (0.5 if distance == 1 else 0.0), note


def _weighed(
    parsed: ParsedResponse,
    results: dict[str, tuple[float, str]],
    threshold: float,
    robot: int,
    team: tuple[int, ...] | None = None,
) -> Validation:
    scores = {k: round(results[k][0], 4) for k in WEIGHTS}
    notes = {k: note for k, (_, note) in results.items() if note}
    quality = round(sum(WEIGHTS[k] * q for k, q in scores.items()), 4)
    return Validation(robot, scores, notes, quality, quality >= threshold, None, parsed, team)


def _team_score(parsed: ParsedResponse, ctx: DecisionContext, threshold: float) -> Validation:
    members, invalid = team_members(parsed, ctx)
    if members is None:
        zeros = dict.fromkeys(WEIGHTS, 0.0)
        return Validation(parsed.robot, zeros, {}, 0.0, False, invalid, parsed)
    results = {**team_criteria(parsed, ctx, members), "phase_consistency": _phase(parsed, ctx)}
    return _weighed(parsed, results, threshold, members[0], members)


def score(
    parsed: ParsedResponse, ctx: DecisionContext, threshold: float = DEFAULT_QUALITY_THRESHOLD
) -> Validation:
    if ctx.team is not None:  # docs/allocation.md#teams
        return _team_score(parsed, ctx, threshold)
    invalid = hard_invalid_reason(parsed, ctx)
    if invalid is not None:
        zeros = dict.fromkeys(WEIGHTS, 0.0)
        return Validation(parsed.robot, zeros, {}, 0.0, False, invalid, parsed)
    choice = parsed.robot
    assert choice is not None  # hard_invalid_reason guarantees it
    rule = rule_for(ctx)
    results = {
        "explanation": _explanation(parsed, ctx, choice),
        "success_accuracy": _accuracy(parsed, ctx, choice),
        "tradeoff_analysis": _tradeoff_analysis(parsed, ctx, choice),
        "workload_awareness": _workload(parsed, ctx, choice),
        "mode_compliance": _mode(ctx, choice, rule),
        "phase_consistency": _phase(parsed, ctx),
        "logical_consistency": _logic(parsed, ctx, choice),
        "confidence_justification": _confidence(parsed, ctx, choice, rule),
    }
    return _weighed(parsed, results, threshold, choice)


def reasoner_failed(error: str) -> Validation:
    """The verdict on an attempt whose reasoner call produced no reply."""
    return Validation(
        None, dict.fromkeys(WEIGHTS, 0.0), {}, 0.0, False, f"the reasoner gave no reply ({error})"
    )


def validate_text(
    text: str, ctx: DecisionContext, threshold: float = DEFAULT_QUALITY_THRESHOLD
) -> Validation:
    """A reply in either format (app.graph.reply_reading): a structured reply that breaks
    its schema is hard-invalid, naming the field; otherwise both are scored alike."""
    read = read_reply(text, ctx)
    if read.schema_error is not None:
        zeros = dict.fromkeys(WEIGHTS, 0.0)
        why = f"the JSON reply breaks its schema: {read.schema_error}"
        return Validation(read.parsed.robot, zeros, {}, 0.0, False, why, read.parsed)
    return score(read.parsed, ctx, threshold)
