"""Claude through the official `anthropic` SDK.

Transport retries, transport failures, unreadable bodies and refused calls are handled
as for every SDK-backed reasoner (app.reasoners.transport): only what the SDK finally
gives up on reaches the graph, as ReasonerError (a failed attempt); a refused call (bad
key, unknown model) is a ReasonerRejectedError that ends the run.

Structured replies (docs/reasoners.md#structured-replies): the decision's JSON Schema is the
input schema of one tool the model is forced to use (`tool_choice`), and the reply's text is
that tool's input as JSON, read by the graph like any structured reply.

Temperature: the pinned SDK (2.x) sends `anthropic-version: 2026-10-21` and no longer has a
`temperature` argument; that API version rejects sampling parameters with HTTP 400. The
service's default is 0.1 (docs/reasoners.md#the-anthropic-reasoner-claude), so a set temperature is
sent in the body (`extra_body`) on the API version that accepts it, 2023-06-01. `temperature=None`
sends no sampling parameter and keeps the SDK's own API version (for models that refuse temperature
altogether).
"""

from __future__ import annotations

import json
import time
from typing import Any

import anthropic
from anthropic.types import Message

from app.domain.decision import DecisionContext
from app.reasoners.base import ReasonerReply
from app.reasoners.structured import ReplySchema
from app.reasoners.transport import (
    DEFAULT_MAX_TOKENS,
    DEFAULT_TEMPERATURE,
    DEFAULT_TIMEOUT_S,
    DEFAULT_TRANSPORT_RETRIES,
    ReasonerRejectedError,
    TierCaps,
    connection_failed,
    parse_reply,
    status_failed,
    tier_caps,
)

__all__ = ["AnthropicReasoner", "ReasonerRejectedError"]

# claude-sonnet-4-5 reaches end-of-life on 2026-11-30 (the SDK warns); 4.6 still takes
# a temperature on API version 2023-06-01.
DEFAULT_MODEL = "claude-sonnet-4-6"
SAMPLING_API_VERSION = "2023-06-01"  # the last API version accepting `temperature`
# Named in the message of a refused call, with what the operator should check.
API = "the Messages API"
CHECK = "the server's ANTHROPIC_API_KEY and model access"


class AnthropicReasoner:
    name = "anthropic"

    def __init__(
        self,
        *,
        api_key: str,
        model: str = DEFAULT_MODEL,
        temperature: float | None = DEFAULT_TEMPERATURE,
        max_tokens: TierCaps | int | tuple[int, ...] = DEFAULT_MAX_TOKENS,
        timeout: float = DEFAULT_TIMEOUT_S,
        transport_retries: int = DEFAULT_TRANSPORT_RETRIES,
        base_url: str | None = None,
    ) -> None:
        self.model = model
        self.temperature = temperature
        self.caps = tier_caps(max_tokens)
        self.transport_retries = transport_retries
        self._client = anthropic.Anthropic(
            api_key=api_key, base_url=base_url, timeout=timeout, max_retries=transport_retries
        )

    def reason(
        self,
        system: str,
        user: str,
        context: DecisionContext,
        schema: ReplySchema | None = None,
    ) -> ReasonerReply:
        return self.complete(system, user, schema=schema, max_tokens=self.caps.at(context.tier))

    def complete(
        self, system: str, user: str, *, schema: ReplySchema | None, max_tokens: int
    ) -> ReasonerReply:
        """One Messages call; with a schema, as forced use of a tool whose input is the
        object (the reply's text is that input as JSON)."""
        options: dict[str, Any] = {}
        if self.temperature is not None:
            options = {
                "extra_body": {"temperature": self.temperature},
                "extra_headers": {"anthropic-version": SAMPLING_API_VERSION},
            }
        if schema is not None:
            options["tools"] = [
                {
                    "name": schema.name,
                    "description": schema.description or "Record the answer.",
                    "input_schema": dict(schema.schema),
                }
            ]
            options["tool_choice"] = {"type": "tool", "name": schema.name}
        started = time.perf_counter()
        try:
            raw = self._client.messages.with_raw_response.create(
                model=self.model,
                max_tokens=max_tokens,
                system=system,
                messages=[{"role": "user", "content": user}],
                **options,
            )
        except anthropic.APIConnectionError as exc:  # includes APITimeoutError
            raise connection_failed(exc) from exc
        except anthropic.APIStatusError as exc:
            raise status_failed(exc, api=API, model=self.model, check=CHECK) from exc
        message = parse_reply(raw, Message)
        latency_ms = (time.perf_counter() - started) * 1000.0
        extra: dict[str, Any] = {
            "stop_reason": message.stop_reason,
            "message_id": message.id,
            "temperature": self.temperature,
        }
        if schema is not None:
            extra["response_format"] = "tool_use"
        return ReasonerReply(
            text=_text_of(message, schema),
            input_tokens=message.usage.input_tokens,
            output_tokens=message.usage.output_tokens,
            latency_ms=latency_ms,
            model=message.model or self.model,
            transport_retries=raw.retries_taken,
            extra=extra,
        )

    def close(self) -> None:
        self._client.close()


def _text_of(message: Message, schema: ReplySchema | None) -> str:
    """The reply as text: the forced tool's input as JSON when a schema was asked (a model
    that answered in words instead is read as markdown), else the text blocks."""
    if schema is not None:
        for block in message.content:
            if getattr(block, "type", None) == "tool_use" and getattr(block, "name", "") == (
                schema.name
            ):
                return json.dumps(getattr(block, "input", {}), ensure_ascii=False)
    return "".join(getattr(block, "text", "") for block in message.content)
