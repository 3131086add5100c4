"""A reply read into the one reply model, whichever format it is in
(docs/reasoners.md#structured-replies).

A reply that opens with '{' is a structured reply: read against the decision's JSON Schema
(app.graph.reply_schema), then mapped field by field onto the `ParsedResponse` the markdown
parser fills (app.graph.parsing). Anything else is the paper's markdown. Both then go
through the same eight criteria, tiers and fallback; what is read depends on the reply, not
on what was asked, so a server that ignored `response_format` is read all the same.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass
from typing import Any

from app.domain.decision import DecisionContext
from app.graph.parsing import ParsedResponse, find_robot, parse_probability, parse_response
from app.graph.reply_schema import decision_schema
from app.reasoners.structured import looks_structured, read_structured


@dataclass(frozen=True)
class ReplyRead:
    parsed: ParsedResponse
    # A structured reply that is not the object its schema describes: why, naming the
    # field (the attempt is hard-invalid). None: read (markdown is never refused here).
    schema_error: str | None = None
    structured: bool = False


def read_reply(text: str, ctx: DecisionContext) -> ReplyRead:
    features = ctx.team.features if ctx.team is not None else ()
    if not looks_structured(text or ""):
        return ReplyRead(parse_response(text, ctx.robot_names, ctx.labels, features))
    read = read_structured(text, decision_schema(ctx))
    parsed = parse_structured(read.value or {}, ctx.robot_names, ctx.labels, features)
    return ReplyRead(parsed, read.error, structured=True)


def _text(value: Any) -> str | None:
    return value.strip() or None if isinstance(value, str) else None


def parse_structured(
    value: Mapping[str, Any],
    names: tuple[str, ...],
    labels: tuple[str, ...],
    features: tuple[str, ...] = (),
) -> ParsedResponse:
    """The reply object as the markdown parser would have read the same answer: a robot by
    label or key, the success as a fraction (70, 70.0 or 0.7 -> 0.7), loads by robot."""
    parsed = ParsedResponse()
    decision = value.get("decision")
    if isinstance(decision, str) and decision.strip():
        parsed.decision_text = decision.strip()
        parsed.robot = find_robot(decision, names, labels)
    success = value.get("expected_success")
    if isinstance(success, int | float) and not isinstance(success, bool):
        parsed.expected_success = parse_probability(f"{success}")
    parsed.reasoning = _text(value.get("reasoning"))
    parsed.tradeoff = _text(value.get("tradeoff"))
    workload = value.get("workload_after")
    if isinstance(workload, Mapping):
        for key, count in workload.items():
            robot = find_robot(str(key), names, labels)
            if robot is not None and isinstance(count, int) and robot not in parsed.workload_after:
                parsed.workload_after[robot] = count
    confidence = value.get("confidence")
    if isinstance(confidence, str) and confidence.lower() in ("high", "medium", "low"):
        parsed.confidence = confidence.lower()
    team = value.get("team")
    if features and isinstance(team, list):
        parsed.team = [line for entry in team if (line := _member(entry, features, names, labels))]
    return parsed


def _member(
    entry: Any, features: tuple[str, ...], names: tuple[str, ...], labels: tuple[str, ...]
) -> dict[str, Any] | None:
    """One `team` entry as the markdown team parser gives a line; None without a feature
    of the task (as a markdown line naming none is skipped)."""
    if not isinstance(entry, Mapping):
        return None
    feature = entry.get("feature")
    if not isinstance(feature, str) or feature not in features:
        return None
    robot = entry.get("robot")
    text = robot.strip() if isinstance(robot, str) else ""
    return {
        "feature": feature,
        "robot": find_robot(text, names, labels) if text else None,
        "text": text,
        "reason": _text(entry.get("reason")) or "",
    }
