"""Structured replies (docs/reasoners.md#structured-replies): the JSON object a model is asked
for, described by a JSON Schema, and the reading of a reply against that schema.

Whoever asks builds the schema (the LTAA graph per decision: app.graph.reply_schema); the
reasoner only carries it to the model with the mechanism its API offers (`ReplyFormat`),
and the same schema judges the reply. A small model's constrained sampler closes every
string within its `maxLength`, so a reply capped at the token limit still parses; one
that does not (a server that ignored the format, a reply cut off anyway) is read here into
a sentence naming the field, never an exception.
"""

from __future__ import annotations

import json
from collections.abc import Mapping
from dataclasses import dataclass
from enum import StrEnum
from typing import Any

from jsonschema import Draft202012Validator
from jsonschema.exceptions import ValidationError, best_match


class ReplyFormat(StrEnum):
    """How a run asks its model for a decision (the setting LTAA_LLM_REPLY_FORMAT, stored
    with the run)."""

    # Chat Completions `response_format: {"type": "json_schema", ...}` (OpenAI, vLLM,
    # Ollama); Anthropic: forced tool use.
    JSON_SCHEMA = "json_schema"
    # `response_format: {"type": "json_object", "schema": ...}`, for servers that refuse
    # json_schema (llama-cpp-python's); Anthropic: forced tool use.
    JSON_OBJECT = "json_object"
    # The paper's markdown sections, free text, read by app.graph.parsing.
    MARKDOWN = "markdown"

    @property
    def structured(self) -> bool:
        return self is not ReplyFormat.MARKDOWN


@dataclass(frozen=True)
class ReplySchema:
    """The JSON object a structured reply must be: `name` (letters, digits, _ and -, as the
    APIs require of a schema's or a tool's name) and a JSON Schema (draft 2020-12)."""

    name: str
    schema: Mapping[str, Any]
    description: str = ""


@dataclass(frozen=True)
class StructuredRead:
    """A reply read against its schema: the object, or why it is not one (naming the
    field). `value` is the parsed object even when it breaks the schema, or None when the
    text holds no JSON object at all."""

    value: dict[str, Any] | None
    error: str | None = None


def json_text(text: str) -> str | None:
    """The JSON object a reply holds, if it holds one: the whole text, or inside a ```json
    fence, or from its first '{' (a model may say a word before it). None: no '{' at all,
    so the reply is free text (markdown)."""
    stripped = text.strip()
    if stripped.startswith("```"):
        stripped = stripped.split("\n", 1)[1] if "\n" in stripped else ""
        stripped = stripped.rsplit("```", 1)[0].strip()
    start = stripped.find("{")
    if start < 0:
        return None
    return stripped[start:]


def looks_structured(text: str) -> bool:
    """Whether a reply is meant as JSON: it opens with '{' (after an optional fence). A
    markdown answer that quotes a brace later stays markdown."""
    stripped = text.strip()
    if stripped.startswith("```"):
        stripped = stripped.split("\n", 1)[1].lstrip() if "\n" in stripped else ""
    return stripped.startswith("{")


def _where(error: ValidationError) -> str:
    path = ""
    for part in error.absolute_path:
        path += f"[{part}]" if isinstance(part, int) else (f".{part}" if path else str(part))
    return path or "the reply"


def read_structured(text: str, schema: ReplySchema) -> StructuredRead:
    """`text` read as the object `schema` describes. Never raises."""
    body = json_text(text or "")
    if body is None:
        return StructuredRead(None, "the reply holds no JSON object")
    try:
        value, _ = json.JSONDecoder().raw_decode(body)
    except json.JSONDecodeError as exc:
        return StructuredRead(
            None,
            f"the reply is not complete JSON ({exc.msg} at character {exc.pos} of "
            f"{len(body)}); a reply cut at the token cap ends this way",
        )
    if not isinstance(value, dict):
        return StructuredRead(None, f"the reply is JSON but not an object ({type(value).__name__})")
    error = best_match(Draft202012Validator(schema.schema).iter_errors(value))
    if error is None:
        return StructuredRead(value)
    return StructuredRead(value, f"field `{_where(error)}`: {_message(error)}")


def _message(error: ValidationError) -> str:
    """jsonschema's message, with the offending value shortened: a 2,000-character string
    over a maxLength would otherwise be quoted whole into the feedback."""
    if error.validator == "maxLength":
        return (
            f"{len(str(error.instance))} characters, more than the {error.validator_value} allowed"
        )
    message = error.message
    return message if len(message) <= 300 else message[:297] + "..."
