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
from app.reasoners.transport import (
    DEFAULT_MAX_TOKENS,
    DEFAULT_TEMPERATURE,
    DEFAULT_TIMEOUT_S,
    DEFAULT_TRANSPORT_RETRIES,
    connection_failed,
    parse_reply,
    status_failed,
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
        max_tokens: int = DEFAULT_MAX_TOKENS,
        timeout: float = DEFAULT_TIMEOUT_S,
        transport_retries: int = DEFAULT_TRANSPORT_RETRIES,
    ) -> None:
        self.model = model
        self.temperature = temperature
        self.max_tokens = max_tokens
        self.transport_retries = transport_retries
        self.base_url = base_url
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

    def reason(self, system: str, user: str, context: DecisionContext) -> ReasonerReply:
        sampling: dict[str, Any] = {}
        if self.temperature is not None:
            sampling["temperature"] = self.temperature
        started = time.perf_counter()
        try:
            raw = self._client.chat.completions.with_raw_response.create(
                model=self.model,
                max_tokens=self.max_tokens,
                messages=[
                    {"role": "system", "content": system},
                    {"role": "user", "content": user},
                ],
                **sampling,
            )
        except openai.APIConnectionError as exc:  # includes APITimeoutError
            raise connection_failed(exc) from exc
        except openai.APIStatusError as exc:
            raise status_failed(exc, api=API, model=self.model, check=CHECK) from exc
        completion = _completion(raw)
        latency_ms = (time.perf_counter() - started) * 1000.0
        choice = completion.choices[0]
        usage = completion.usage
        extra: dict[str, Any] = {
            "stop_reason": choice.finish_reason,
            "message_id": completion.id,
            "temperature": self.temperature,
        }
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
