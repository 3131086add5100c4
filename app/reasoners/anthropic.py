"""Claude through the official `anthropic` SDK.

The SDK is the transport layer: it retries connection errors, timeouts, 408, 409, 429 and
5xx itself (SDK 2.10, `_should_retry`), waiting what `retry-after` (or `retry-after-ms`)
says, else an exponential backoff from 0.5 s. Only what it finally gives up on reaches the
graph, as ReasonerError, which the graph counts as a failed attempt (validation retries
are a separate budget). So does a 200 whose body is no Message (empty, cut off, an HTML
page from a proxy): the SDK would hand those back unparsed or raise a bare ValueError.

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
from app.reasoners.base import ReasonerError, ReasonerReply

# claude-sonnet-4-5 reaches end-of-life on 2026-11-30 (the SDK warns); 4.6 still takes
# a temperature on API version 2023-06-01.
DEFAULT_MODEL = "claude-sonnet-4-6"
DEFAULT_TEMPERATURE = 0.1
DEFAULT_MAX_TOKENS = 700  # the required answer is ~150-300 tokens; room for a long one
DEFAULT_TIMEOUT_S = 60.0
DEFAULT_TRANSPORT_RETRIES = 3
SAMPLING_API_VERSION = "2023-06-01"  # the last API version accepting `temperature`
# Statuses worth another try later (after the SDK's own retries): the rest are our fault.
_TRANSIENT_STATUSES = {408, 409, 429}


def _transient(exc: anthropic.APIStatusError) -> bool:
    return exc.status_code in _TRANSIENT_STATUSES or exc.status_code >= 500


def _retries_taken(exc: anthropic.APIError) -> int:
    """The SDK numbers each try in a request header; the last try's number is the retries."""
    try:
        return int(exc.request.headers.get("x-stainless-retry-count", 0))
    except ValueError:
        return 0


def _message(raw: anthropic.APIResponse[Any]) -> Message:
    """The reply body as a Message, validated: the SDK's lenient parse() would return a str
    for a non-JSON content type, a Message without its fields for JSON of another shape,
    and raise a bare ValueError for an empty or cut-off body."""
    body: bytes = raw.http_response.content
    try:
        return Message.model_validate_json(body)
    except pydantic.ValidationError as exc:
        first = exc.errors()[0]
        where = ".".join(str(part) for part in first["loc"]) or "body"
        raise ReasonerError(
            f"unreadable reply (HTTP {raw.status_code}, {len(body)} bytes, "
            f"{raw.headers.get('content-type', 'no content-type')}): {where}: {first['msg']}",
            transport_retries=raw.retries_taken,
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
            retries = _retries_taken(exc)
            raise ReasonerError(
                f"{type(exc).__name__} after {retries} transport retries: {exc}",
                transport_retries=retries,
            ) from exc
        except anthropic.APIStatusError as exc:
            if not _transient(exc):
                raise _rejected(exc, self.model) from exc
            retries = _retries_taken(exc)
            raise ReasonerError(
                f"HTTP {exc.status_code} after {retries} transport retries: {exc}",
                transport_retries=retries,
            ) from exc
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


class ReasonerRejectedError(DomainError):
    """The Messages API refused the call itself (bad key, unknown model): retrying cannot
    help, so the run or request fails with this message instead of escalating tiers."""


def _rejected(exc: anthropic.APIStatusError, model: str) -> DomainError:
    if exc.status_code == 404:
        err = ReasonerRejectedError(
            "model",
            f"the Messages API does not know model '{model}' (HTTP 404); choose another model",
            code="unknown_model",
        )
        return err
    err = ReasonerRejectedError(
        "reasoner",
        f"the Messages API rejected the call (HTTP {exc.status_code}: "
        f"{exc.message}); check the server's ANTHROPIC_API_KEY and model access",
        code="upstream_rejected",
    )
    # The server's own configuration, not the request, is at fault.
    err.status_code = 502 if exc.status_code in (401, 403) else 422
    return err
