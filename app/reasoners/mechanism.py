"""Which dialect of structured output a Chat Completions server takes
(docs/reasoners.md#structured-replies).

OpenAI, vLLM and Ollama take `response_format: {"type": "json_schema", "json_schema":
{...}}`; llama-cpp-python's server refuses it (HTTP 500 naming `response_format`) and takes
`{"type": "json_object", "schema": {...}}` instead. A run asks in the format its settings
name; a server that refuses json_schema is asked again at once in the json_object dialect,
and for the rest of the run (the refusal costs the SDK's retries once: about 3 s with the
default 3 retries). Detection never ends a run: a refusal that does not name the
format is the call's own failure, as before.
"""

from __future__ import annotations

from typing import Any

from app.reasoners.structured import ReplyFormat, ReplySchema

# Statuses a server answers an unknown `response_format` with: 400 (OpenAI's own), 422
# (pydantic-validated servers), 500 (llama-cpp-python 0.3.x).
REFUSAL_STATUSES = frozenset({400, 422, 500})
_NAMES_THE_FORMAT = ("response_format", "json_schema")


def response_format(schema: ReplySchema, asked: ReplyFormat) -> dict[str, Any]:
    """The request body's `response_format` for `schema` in the dialect `asked`."""
    if asked is ReplyFormat.JSON_OBJECT:
        return {"type": "json_object", "schema": dict(schema.schema)}
    # strict: off. OpenAI's strict mode refuses keywords the decision schema relies on
    # (maxLength); the reply is checked against the schema here all the same.
    return {
        "type": "json_schema",
        "json_schema": {"name": schema.name, "schema": dict(schema.schema), "strict": False},
    }


class StructuredMechanism:
    """The dialect one reasoner (one run) uses, learnt from the server's answers."""

    def __init__(self, reply_format: ReplyFormat) -> None:
        self.requested = reply_format
        self.current = (
            ReplyFormat.JSON_OBJECT
            if reply_format is ReplyFormat.JSON_OBJECT
            else ReplyFormat.JSON_SCHEMA
        )

    def refused(self, status: int, message: str) -> bool:
        """Whether an error answer refuses the json_schema dialect; if so, json_object is
        used from now on."""
        if self.current is not ReplyFormat.JSON_SCHEMA or status not in REFUSAL_STATUSES:
            return False
        if not any(name in (message or "") for name in _NAMES_THE_FORMAT):
            return False
        self.current = ReplyFormat.JSON_OBJECT
        return True
