"""The JSON Schema of one decision's structured reply (docs/reasoners.md#structured-replies).

Built per decision from its true facts, so what the model may say is what validation may
accept: the robot (a team task: each unit's member) one of the robots allowed now, the
confidence one of three words, every robot's load after the decision, and each free text
capped by a `maxLength` so that a reply written to the cap still closes its JSON. The same
schema is sent (response_format, or the forced tool's input schema) and reads the reply
back (app.reasoners.structured.read_structured); a pure function of the context, so a
resumed or replayed run judges a recorded reply exactly as the first time.
"""

from __future__ import annotations

from typing import Any

from app.domain.decision import DecisionContext
from app.reasoners.structured import ReplySchema

DECISION_SCHEMA = "allocation_decision"
REASONING_CHARS = 200  # 2-4 short sentences
TRADEOFF_CHARS = 120
MEMBER_REASON_CHARS = 100  # one sentence per team member
CONFIDENCE = ("High", "Medium", "Low")


def allowed_labels(ctx: DecisionContext) -> list[str]:
    """How the reply names the robots the decision may choose: by label, as the prompt
    does (by key where two robots share a label, so the name is never ambiguous)."""
    return [robot_names(ctx)[r] for r in ctx.feasible]


def robot_names(ctx: DecisionContext) -> tuple[str, ...]:
    labels = ctx.labels
    lowered = [label.lower() for label in labels]
    return labels if len(set(lowered)) == len(lowered) else ctx.robot_names


def _text(limit: int, what: str) -> dict[str, Any]:
    return {"type": "string", "minLength": 1, "maxLength": limit, "description": what}


def decision_schema(ctx: DecisionContext) -> ReplySchema:
    names = robot_names(ctx)
    allowed = allowed_labels(ctx)
    properties: dict[str, Any] = {
        "decision": {
            "type": "string",
            "enum": allowed,
            "description": "the robot chosen"
            + (" (a team task: the member covering the first unit)" if ctx.team else ""),
        },
    }
    if ctx.team is not None:
        units = len(ctx.team.units)
        properties["team"] = {
            "type": "array",
            "minItems": units,
            "maxItems": units,
            "description": "one entry per unit, in the order of the units",
            "items": {
                "type": "object",
                "properties": {
                    "feature": {"type": "string", "enum": list(ctx.team.features)},
                    "robot": {"type": "string", "enum": allowed},
                    "reason": _text(MEMBER_REASON_CHARS, "why this robot, citing its rate"),
                },
                "required": ["feature", "robot", "reason"],
                "additionalProperties": False,
            },
        }
    properties |= {
        "expected_success": {
            "type": "number",
            "minimum": 0,
            "maximum": 100,
            "description": "S of the choice in percent, e.g. 70.0",
        },
        "reasoning": _text(REASONING_CHARS, "2-4 sentences citing S values, loads, phase"),
        "workload_after": {
            "type": "object",
            "properties": {name: {"type": "integer", "minimum": 0} for name in names},
            "required": list(names),
            "additionalProperties": False,
            "description": "every robot's load after this decision",
        },
        "confidence": {"type": "string", "enum": list(CONFIDENCE)},
        "tradeoff": _text(TRADEOFF_CHARS, "best vs least-loaded, the gap in points, the rule"),
    }
    return ReplySchema(
        name=DECISION_SCHEMA,
        schema={
            "type": "object",
            "properties": properties,
            "required": list(properties),
            "additionalProperties": False,
        },
        description="Record the allocation decision and its justification.",
    )
