"""Reasoners by name, with the errors a request deserves when one cannot be built."""

from __future__ import annotations

import os
from collections.abc import Callable, Mapping
from typing import Any, Protocol

from pydantic import SecretStr

from app.domain.errors import DomainError
from app.reasoners.base import Reasoner, close_reasoner
from app.reasoners.replay import RecordedReply, ReplayReasoner, ReplyKey
from app.reasoners.rules import RulesReasoner
from app.reasoners.scope import DEFAULT_LLM_MARGIN, scoped
from app.reasoners.structured import ReplyFormat
from app.reasoners.transport import DEFAULT_MAX_TOKENS

REASONERS = ("rules", "anthropic", "openai", "replay")
LLM_REASONERS = ("anthropic", "openai")  # the ones that call a model (and cost tokens)
API_KEY_VARS = ("LTAA_ANTHROPIC_API_KEY", "ANTHROPIC_API_KEY")


class ReasonerSettings(Protocol):
    """The fields of app.config.Settings the factory reads (any object with them will do)."""

    anthropic_api_key: SecretStr | None
    anthropic_base_url: str | None
    anthropic_timeout_s: float
    anthropic_max_transport_retries: int
    default_model: str
    openai_base_url: str | None
    openai_api_key: SecretStr | None
    openai_model: str | None
    openai_timeout_s: float
    openai_max_transport_retries: int
    llm_max_tokens: list[int]


def _secret(value: SecretStr | str | None) -> str | None:
    if isinstance(value, SecretStr):
        value = value.get_secret_value()
    return value or None


def resolve_api_key(explicit: SecretStr | str | None, settings: Any = None) -> str | None:
    """Explicit argument, then settings, then LTAA_ANTHROPIC_API_KEY, then ANTHROPIC_API_KEY."""
    key = _secret(explicit) or _secret(getattr(settings, "anthropic_api_key", None))
    if key:
        return key
    return next((os.environ[v] for v in API_KEY_VARS if os.environ.get(v)), None)


def check_reasoner(
    name: str,
    *,
    settings: ReasonerSettings | None = None,
    model: str | None = None,
    temperature: float | None = None,
) -> None:
    """Refuse (DomainError) a reasoner this server cannot build: unknown, or its key
    missing. It is built and closed at once; a run builds its own when it starts."""
    close_reasoner(make_reasoner(name, settings=settings, model=model, temperature=temperature))


def make_reasoner(
    name: str,
    *,
    settings: ReasonerSettings | None = None,
    model: str | None = None,
    temperature: float | None = None,
    api_key: SecretStr | str | None = None,
    base_url: str | None = None,
    timeout: float | None = None,
    transport_retries: int | None = None,
    replay_of: str | None = None,
    replies: Mapping[ReplyKey, RecordedReply] | None = None,
    llm_scope: str = "all",
    llm_margin: float | None = None,
    reply_format: str = ReplyFormat.JSON_SCHEMA.value,
) -> Reasoner:
    """Explicit arguments win over settings, which win over the reasoner's defaults.
    `reply_format` (docs/reasoners.md#structured-replies): the dialect an `openai` reasoner
    asks a structured reply in (the graph decides whether to ask for one).

    'replay' reads no database: the caller loads the recorded replies of run `replay_of`
    and passes them in `replies`. `llm_scope` 'contested' asks an LLM reasoner only for
    contested decisions (app.reasoners.scope); 'rules' and 'replay' answer every one.
    """
    reasoner = _make_reasoner(
        name,
        settings=settings,
        model=model,
        temperature=temperature,
        api_key=api_key,
        base_url=base_url,
        timeout=timeout,
        transport_retries=transport_retries,
        replay_of=replay_of,
        replies=replies,
        reply_format=ReplyFormat(reply_format),
    )
    if name not in LLM_REASONERS:
        return reasoner

    return scoped(reasoner, llm_scope, DEFAULT_LLM_MARGIN if llm_margin is None else llm_margin)


def _make_reasoner(
    name: str,
    *,
    settings: ReasonerSettings | None,
    model: str | None,
    temperature: float | None,
    api_key: SecretStr | str | None,
    base_url: str | None,
    timeout: float | None,
    transport_retries: int | None,
    replay_of: str | None,
    replies: Mapping[ReplyKey, RecordedReply] | None,
    reply_format: ReplyFormat,
) -> Reasoner:
    if name == "rules":
        return RulesReasoner()
    if name == "replay":
        if replay_of is None or replies is None:
            raise DomainError(
                "reasoner",
                "the 'replay' reasoner replays a finished durable run: "
                'POST /runs with "reasoner": "replay" and "replay_of": <run id>',
                code="replay_needs_run",
            )
        return ReplayReasoner(run_id=replay_of, replies=replies)
    if name not in LLM_REASONERS:
        raise DomainError(
            "reasoner",
            f"unknown reasoner '{name}'; choose one of: {', '.join(REASONERS)}",
            code="unknown_reasoner",
        )

    def pick(explicit: Any, setting: str, default: Any) -> Any:
        if explicit is not None:
            return explicit
        value = getattr(settings, setting, None) if settings is not None else None
        return value if value is not None else default

    if name == "openai":
        return _openai_reasoner(
            pick=pick,
            model=model,
            temperature=temperature,
            api_key=api_key,
            base_url=base_url,
            timeout=timeout,
            transport_retries=transport_retries,
            reply_format=reply_format,
        )
    key = resolve_api_key(api_key, settings)
    if key is None:
        raise DomainError(
            "reasoner",
            "the 'anthropic' reasoner needs an API key and none is configured: set "
            "ANTHROPIC_API_KEY (or LTAA_ANTHROPIC_API_KEY) in the server's environment, or use "
            "the offline 'rules' reasoner",
            code="missing_api_key",
        )

    # Imported here: the SDK takes ~2 s to import and offline deployments never need it.
    from app.reasoners import anthropic as anthropic_reasoner

    return anthropic_reasoner.AnthropicReasoner(
        api_key=key,
        model=pick(model, "default_model", anthropic_reasoner.DEFAULT_MODEL),
        temperature=temperature
        if temperature is not None
        else anthropic_reasoner.DEFAULT_TEMPERATURE,
        timeout=pick(timeout, "anthropic_timeout_s", anthropic_reasoner.DEFAULT_TIMEOUT_S),
        transport_retries=pick(
            transport_retries,
            "anthropic_max_transport_retries",
            anthropic_reasoner.DEFAULT_TRANSPORT_RETRIES,
        ),
        base_url=pick(base_url, "anthropic_base_url", None),
        max_tokens=tuple(pick(None, "llm_max_tokens", DEFAULT_MAX_TOKENS)),
    )


def _missing_setting(setting: str, what: str) -> DomainError:
    return DomainError(
        "reasoner",
        f"the 'openai' reasoner needs {what} and none is configured: set {setting} in the "
        "server's environment (the SDK's own OPENAI_* variables are never read, so site "
        "data cannot go to a default host), or use the offline 'rules' reasoner",
        code="missing_setting",
    )


def _openai_reasoner(
    *,
    pick: Callable[[Any, str, Any], Any],
    model: str | None,
    temperature: float | None,
    api_key: SecretStr | str | None,
    base_url: str | None,
    timeout: float | None,
    transport_retries: int | None,
    reply_format: ReplyFormat,
) -> Reasoner:
    """Base URL and model are required; nothing falls back to OPENAI_* or a default host."""
    url = pick(base_url, "openai_base_url", None)
    if not url:
        raise _missing_setting("LTAA_OPENAI_BASE_URL", "the base URL of a Chat Completions server")
    chosen_model = pick(model, "openai_model", None)
    if not chosen_model:
        raise _missing_setting("LTAA_OPENAI_MODEL", "a model name")
    # Imported here: offline deployments never need the SDK.
    from app.reasoners import openai as openai_reasoner

    return openai_reasoner.OpenAIReasoner(
        base_url=url,
        model=chosen_model,
        api_key=_secret(api_key) or _secret(pick(None, "openai_api_key", None)),
        temperature=temperature if temperature is not None else openai_reasoner.DEFAULT_TEMPERATURE,
        timeout=pick(timeout, "openai_timeout_s", openai_reasoner.DEFAULT_TIMEOUT_S),
        transport_retries=pick(
            transport_retries,
            "openai_max_transport_retries",
            openai_reasoner.DEFAULT_TRANSPORT_RETRIES,
        ),
        max_tokens=tuple(pick(None, "llm_max_tokens", DEFAULT_MAX_TOKENS)),
        reply_format=reply_format,
    )
