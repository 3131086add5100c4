"""Any OpenAI-compatible Chat Completions server through the official `openai` SDK: vLLM,
Ollama, llama.cpp server, LM Studio, or OpenAI itself.

Transport retries, transport failures, unreadable bodies and refused calls are handled
as for every SDK-backed reasoner (app.reasoners.transport), so the graph sees the same
errors as from `anthropic`.

Where site data goes is decided by the server's LTAA_* settings alone. The SDK would fill
in whatever it is not given from its own environment (SDK 3.51, openai/lib/_client_auth.py):
OPENAI_API_KEY, OPENAI_ADMIN_KEY, OPENAI_ORG_ID, OPENAI_PROJECT_ID, OPENAI_WEBHOOK_SECRET,
OPENAI_BASE_URL (else https://api.openai.com/v1) and OPENAI_CUSTOM_HEADERS; its HTTP
client would read HTTP(S)_PROXY / ALL_PROXY / NO_PROXY, SSL_CERT_FILE and ~/.netrc, and
follow redirects to any host. So the base URL and key are always passed (a placeholder
key for servers that need none), the identity fields the constructor could only take
from the environment are cleared after it, and the HTTP client is built with
trust_env=False and no redirects. (OPENAI_LOG only sets the SDK logger's level, and
OPENAI_API_TYPE / OPENAI_API_VERSION / AZURE_OPENAI_ENDPOINT only configure the SDK's
module-level client, which is never used.)
"""

from __future__ import annotations

import time
from typing import Any

import httpx2
import openai
from openai._legacy_response import LegacyAPIResponse
from openai.types.chat import ChatCompletion

from app.domain.decision import DecisionContext
from app.reasoners.base import ReasonerError, ReasonerReply
from app.reasoners.mechanism import StructuredMechanism, response_format
from app.reasoners.structured import ReplyFormat, ReplySchema
from app.reasoners.transport import (
    DEFAULT_MAX_TOKENS,
    DEFAULT_TEMPERATURE,
    DEFAULT_TIMEOUT_S,
    DEFAULT_TRANSPORT_RETRIES,
    TierCaps,
    connection_failed,
    parse_reply,
    status_failed,
    tier_caps,
)

# Named in the message of a refused call, with what the operator should check.
API = "the Chat Completions server"
CHECK = "the server's LTAA_OPENAI_API_KEY, LTAA_OPENAI_MODEL and LTAA_OPENAI_BASE_URL"

# Local servers (vLLM without --api-key, Ollama, llama.cpp) take any bearer token; the SDK
# refuses to start without one and would otherwise read OPENAI_API_KEY.
NO_KEY = "no-key"


def _completion(raw: LegacyAPIResponse[Any]) -> ChatCompletion:
    """The reply body as a ChatCompletion, validated, with a choice to read."""
    completion = parse_reply(raw, ChatCompletion)
    if not completion.choices:
        raise ReasonerError(
            f"unreadable reply (HTTP {raw.status_code}, "
            f"{len(raw.http_response.content)} bytes): no choices",
            transport_retries=raw.retries_taken,
        )
    return completion


class OpenAIReasoner:
    name = "openai"

    def __init__(
        self,
        *,
        base_url: str,
        model: str,
        api_key: str | None = None,
        temperature: float | None = DEFAULT_TEMPERATURE,
        max_tokens: TierCaps | int | tuple[int, ...] = DEFAULT_MAX_TOKENS,
        timeout: float = DEFAULT_TIMEOUT_S,
        transport_retries: int = DEFAULT_TRANSPORT_RETRIES,
        reply_format: ReplyFormat = ReplyFormat.JSON_SCHEMA,
    ) -> None:
        self.model = model
        self.temperature = temperature
        self.caps = tier_caps(max_tokens)
        self.transport_retries = transport_retries
        self.base_url = base_url
        self.mechanism = StructuredMechanism(reply_format)
        self._http = httpx2.Client(trust_env=False, follow_redirects=False, timeout=timeout)
        self._client = openai.OpenAI(
            api_key=api_key or NO_KEY,
            base_url=base_url,
            timeout=timeout,
            max_retries=transport_retries,
            http_client=self._http,
            default_headers={},
        )
        _forget_environment(self._client)

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
        """One Chat Completions call; with a schema, in the dialect the server takes
        (json_schema, or json_object + schema once the server has refused json_schema)."""
        started = time.perf_counter()
        messages: list[dict[str, str]] = [
            {"role": "system", "content": system},
            {"role": "user", "content": user},
        ]
        asked = self.mechanism.current if schema is not None else None
        try:
            try:
                raw = self._create(messages, max_tokens, schema, asked)
            except openai.APIStatusError as exc:
                if schema is None or not self.mechanism.refused(exc.status_code, exc.message):
                    raise
                # The server does not take json_schema (llama-cpp-python answers 500 naming
                # the field, after the SDK's retries): ask again in its own dialect, and so
                # for the rest of the run.
                asked = self.mechanism.current
                raw = self._create(messages, max_tokens, schema, asked)
        except openai.APIConnectionError as exc:  # includes APITimeoutError
            raise connection_failed(exc) from exc
        except openai.APIStatusError as exc:
            raise status_failed(exc, api=API, model=self.model, check=CHECK) from exc
        return self._reply(raw, started, asked)

    def _create(
        self,
        messages: list[dict[str, str]],
        max_tokens: int,
        schema: ReplySchema | None,
        asked: ReplyFormat | None,
    ) -> LegacyAPIResponse[Any]:
        sampling: dict[str, Any] = {}
        if self.temperature is not None:
            sampling["temperature"] = self.temperature
        if schema is not None and asked is not None:
            sampling["extra_body"] = {"response_format": response_format(schema, asked)}
        return self._client.chat.completions.with_raw_response.create(
            model=self.model,
            max_tokens=max_tokens,
            messages=messages,  # type: ignore[arg-type]
            **sampling,
        )

    def _reply(
        self, raw: LegacyAPIResponse[Any], started: float, asked: ReplyFormat | None
    ) -> ReasonerReply:
        completion = _completion(raw)
        latency_ms = (time.perf_counter() - started) * 1000.0
        choice = completion.choices[0]
        usage = completion.usage
        extra: dict[str, Any] = {
            "stop_reason": choice.finish_reason,
            "message_id": completion.id,
            "temperature": self.temperature,
        }
        if asked is not None:
            extra["response_format"] = asked.value
        return ReasonerReply(
            text=choice.message.content or "",
            input_tokens=usage.prompt_tokens if usage else 0,
            output_tokens=usage.completion_tokens if usage else 0,
            latency_ms=latency_ms,
            model=completion.model or self.model,
            transport_retries=raw.retries_taken,
            extra=extra,
        )

    def close(self) -> None:
        self._client.close()
        self._http.close()


def _forget_environment(client: openai.OpenAI) -> None:
    """Clear what the constructor took from OPENAI_* variables for lack of an argument:
    an explicit None would be read from the environment again, and "" is sent as an empty
    header."""
    client.organization = None
    client.project = None
    client.admin_api_key = None
    client.webhook_secret = None
    client._custom_headers = {}  # OPENAI_CUSTOM_HEADERS, parsed unconditionally
    client._ambient_authorizations = frozenset()
