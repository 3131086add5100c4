"""Claude through the official `anthropic` SDK.

Transport retries, transport failures, unreadable bodies and refused calls are handled
as for every SDK-backed reasoner (app.reasoners.transport): only what the SDK finally
gives up on reaches the graph, as ReasonerError (a failed attempt); a refused call (bad
key, unknown model) is a ReasonerRejectedError that ends the run.

Temperature: the pinned SDK (2.x) sends `anthropic-version: 2026-10-21` and no longer has a
`temperature` argument; that API version rejects sampling parameters with HTTP 400. The
SPEC asks for 0.1, so a set temperature is sent in the body (`extra_body`) on the API
version that accepts it, 2023-06-01. `temperature=None` sends no sampling parameter and
keeps the SDK's own API version (for models that refuse temperature altogether).
"""

from __future__ import annotations

import time
from typing import Any

import anthropic
import pydantic
from anthropic.types import Message

from app.domain.decision import DecisionContext
from app.domain.errors import DomainError
from app.reasoners.base import ReasonerReply
from app.reasoners.transport import (
    ReasonerRejectedError,
    gave_up,
    rejected,
    transient,
    unreadable,
)

__all__ = ["AnthropicReasoner", "ReasonerRejectedError"]

# claude-sonnet-4-5 reaches end-of-life on 2026-11-30 (the SDK warns); 4.6 still takes
# a temperature on API version 2023-06-01.
DEFAULT_MODEL = "claude-sonnet-4-6"
DEFAULT_TEMPERATURE = 0.1
DEFAULT_MAX_TOKENS = 700  # the required answer is ~150-300 tokens; room for a long one
DEFAULT_TIMEOUT_S = 60.0
DEFAULT_TRANSPORT_RETRIES = 3
SAMPLING_API_VERSION = "2023-06-01"  # the last API version accepting `temperature`


def _message(raw: anthropic.APIResponse[Any]) -> Message:
    """The reply body as a Message, validated: the SDK's lenient parse() would return a str
    for a non-JSON content type, a Message without its fields for JSON of another shape,
    and raise a bare ValueError for an empty or cut-off body."""
    body: bytes = raw.http_response.content
    try:
        return Message.model_validate_json(body)
    except pydantic.ValidationError as exc:
        raise unreadable(
            exc,
            status=raw.status_code,
            body=body,
            content_type=raw.headers.get("content-type"),
            retries=raw.retries_taken,
        ) from exc


class AnthropicReasoner:
    name = "anthropic"

    def __init__(
        self,
        *,
        api_key: str,
        model: str = DEFAULT_MODEL,
        temperature: float | None = DEFAULT_TEMPERATURE,
        max_tokens: int = DEFAULT_MAX_TOKENS,
        timeout: float = DEFAULT_TIMEOUT_S,
        transport_retries: int = DEFAULT_TRANSPORT_RETRIES,
        base_url: str | None = None,
    ) -> None:
        self.model = model
        self.temperature = temperature
        self.max_tokens = max_tokens
        self.transport_retries = transport_retries
        self._client = anthropic.Anthropic(
            api_key=api_key, base_url=base_url, timeout=timeout, max_retries=transport_retries
        )

    def reason(self, system: str, user: str, context: DecisionContext) -> ReasonerReply:
        sampling: dict[str, Any] = {}
        if self.temperature is not None:
            sampling = {
                "extra_body": {"temperature": self.temperature},
                "extra_headers": {"anthropic-version": SAMPLING_API_VERSION},
            }
        started = time.perf_counter()
        try:
            raw = self._client.messages.with_raw_response.create(
                model=self.model,
                max_tokens=self.max_tokens,
                system=system,
                messages=[{"role": "user", "content": user}],
                **sampling,
            )
        except anthropic.APIConnectionError as exc:  # includes APITimeoutError
            raise gave_up(exc, type(exc).__name__) from exc
        except anthropic.APIStatusError as exc:
            if not transient(exc.status_code):
                raise _rejected(exc, self.model) from exc
            raise gave_up(exc, f"HTTP {exc.status_code}") from exc
        message = _message(raw)
        latency_ms = (time.perf_counter() - started) * 1000.0
        text = "".join(getattr(block, "text", "") for block in message.content)
        extra: dict[str, Any] = {
            "stop_reason": message.stop_reason,
            "message_id": message.id,
            "temperature": self.temperature,
        }
        return ReasonerReply(
            text=text,
            input_tokens=message.usage.input_tokens,
            output_tokens=message.usage.output_tokens,
            latency_ms=latency_ms,
            model=message.model or self.model,
            transport_retries=raw.retries_taken,
            extra=extra,
        )

    def close(self) -> None:
        self._client.close()


def _rejected(exc: anthropic.APIStatusError, model: str) -> DomainError:
    return rejected(
        api="the Messages API",
        status=exc.status_code,
        message=exc.message,
        model=model,
        check="the server's ANTHROPIC_API_KEY and model access",
    )
