"""Structured replies (docs/reasoners.md#structured-replies): the per-decision schema, the
reading of a JSON reply into the one reply model, and that both formats meet the same
eight criteria: the same answer scores the same in markdown and in JSON."""

from __future__ import annotations

import json
from dataclasses import replace
from typing import Any

import pytest
from jsonschema import Draft202012Validator

from app.domain.decision import TeamFacts
from app.graph.prompts import prompt_for, system_prompt
from app.graph.reply_reading import read_reply
from app.graph.reply_schema import REASONING_CHARS, decision_schema
from app.graph.validation import validate_text
from app.reasoners.rules import compose_answer
from app.reasoners.structured import ReplyFormat, read_structured
from tests.fakes.structured_replies import as_structured
from tests.support.ltaa_support import context

CTX = context()  # middle phase, balanced; the rule picks Heavy Robot
TEAM_CTX = context(
    features=("heavy", "careful"),
    feasible=(0, 1, 2),
    team=TeamFacts(
        units=("heavy", "careful"),
        rates=((0.5, 0.7, 0.9), (0.95, 0.6, 0.4)),
        best=(2, 0),
        fewest=(0, 1),
    ),
)


def as_json(markdown: str, ctx: Any = CTX) -> str:
    """The answer as a constrained server writes it for this decision's schema."""
    return as_structured(markdown, dict(decision_schema(ctx).schema))


def test_the_schema_is_valid_json_schema_and_allows_only_the_robots_allowed_now() -> None:
    ctx = replace(CTX, feasible=(0, 2))
    schema = decision_schema(ctx).schema
    Draft202012Validator.check_schema(schema)
    assert schema["properties"]["decision"]["enum"] == ["Light Robot", "Heavy Robot"]
    assert set(schema["properties"]["workload_after"]["required"]) == set(ctx.labels)
    assert schema["required"] == list(schema["properties"]) and not schema["additionalProperties"]
    assert schema["properties"]["reasoning"]["maxLength"] == REASONING_CHARS


def test_a_team_schema_asks_one_member_per_unit() -> None:
    schema = decision_schema(TEAM_CTX).schema
    Draft202012Validator.check_schema(schema)
    team = schema["properties"]["team"]
    assert team["minItems"] == team["maxItems"] == 2
    assert team["items"]["properties"]["feature"]["enum"] == ["heavy", "careful"]


def test_robots_sharing_a_label_are_named_by_key() -> None:
    ctx = replace(CTX, robot_labels=("Robot", "Robot", "Heavy Robot"))
    assert decision_schema(ctx).schema["properties"]["decision"]["enum"] == [
        "light",
        "medium",
        "heavy",
    ]


@pytest.mark.parametrize("ctx", [CTX, TEAM_CTX], ids=["one robot", "team"])
def test_the_same_answer_scores_the_same_in_either_format(ctx: Any) -> None:
    markdown = compose_answer(ctx)
    structured = as_json(markdown, ctx)
    assert read_structured(structured, decision_schema(ctx)).error is None
    by_markdown, by_json = validate_text(markdown, ctx), validate_text(structured, ctx)
    assert by_json.accepted and by_json.robot == by_markdown.robot
    assert by_json.team == by_markdown.team
    # The rules' reasoning is cut to the schema's maxLength at a sentence: the criteria that
    # read it may differ by that; everything else scores alike.
    differs = {"explanation", "phase_consistency", "tradeoff_analysis"}
    for name, value in by_markdown.scores.items():
        if name not in differs:
            assert by_json.scores[name] == value, name


def test_a_reply_in_a_fence_or_after_a_word_is_read() -> None:
    structured = as_json(compose_answer(CTX))
    for text in (f"```json\n{structured}\n```", f"  {structured}  "):
        assert validate_text(text, CTX).accepted


BREAKS = {
    "an unknown robot": (
        {"decision": "Flying Robot"},
        "field `decision`: 'Flying Robot' is not one of",
    ),
    "a robot the cap forbids": (
        {"decision": "Light Robot"},
        "field `decision`: 'Light Robot' is not one of ['Medium Robot', 'Heavy Robot']",
    ),
    "a field missing": ({"confidence": None}, "'confidence' is a required property"),
    "a word for a number": ({"expected_success": "high"}, "field `expected_success`"),
    "a load for no robot": (
        {"workload_after": {"Light Robot": 3, "Medium Robot": 5, "Heavy Robot": 7, "X": 1}},
        "field `workload_after`",
    ),
    "reasoning past its cap": (
        {"reasoning": "x" * 2_000},
        f"field `reasoning`: 2000 characters, more than the {REASONING_CHARS} allowed",
    ),
}


@pytest.mark.parametrize("change,why", BREAKS.values(), ids=BREAKS.keys())
def test_json_that_breaks_the_schema_is_hard_invalid_naming_the_field(
    change: dict[str, Any], why: str
) -> None:
    ctx = replace(CTX, feasible=(1, 2))
    reply = json.loads(as_json(compose_answer(ctx), ctx))
    for key, value in change.items():
        if value is None:
            del reply[key]
        else:
            reply[key] = value
    verdict = validate_text(json.dumps(reply), ctx)
    assert verdict.quality == 0.0 and not verdict.accepted
    assert verdict.hard_invalid is not None and why in verdict.hard_invalid


def test_json_cut_at_the_token_cap_says_so() -> None:
    structured = as_json(compose_answer(CTX))
    verdict = validate_text(structured[: len(structured) // 2], CTX)
    assert verdict.hard_invalid is not None
    assert "not complete JSON" in verdict.hard_invalid and "token cap" in verdict.hard_invalid


def test_markdown_stays_markdown_even_when_it_quotes_a_brace() -> None:
    text = compose_answer(CTX).replace("**Reasoning**: ", "**Reasoning**: {sic} ")
    read = read_reply(text, CTX)
    assert not read.structured and read.schema_error is None and read.parsed.robot == 2


def test_structured_prompts_ask_for_the_object_at_every_tier() -> None:
    for ctx in (CTX, TEAM_CTX):
        for tier in range(4):
            text = prompt_for(
                ctx, tier, feedback="- fix it", quality=0.3, fmt=ReplyFormat.JSON_OBJECT
            )
            assert '"decision"' in text and "**Decision**" not in text, (tier, text)
            assert "Heavy Robot" in text
    assert "JSON object" in system_prompt(ReplyFormat.JSON_SCHEMA)
    assert "markdown" in system_prompt(ReplyFormat.MARKDOWN)
