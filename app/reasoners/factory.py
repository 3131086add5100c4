"""Reasoners by name, with the errors a request deserves when one cannot be built."""

from __future__ import annotations

import os
from collections.abc import Mapping
from typing import Any, Protocol

from pydantic import SecretStr

from app.domain.errors import DomainError
from app.reasoners.base import Reasoner
from app.reasoners.replay import RecordedReply, ReplayReasoner, ReplyKey
from app.reasoners.rules import RulesReasoner

REASONERS = ("rules", "anthropic", "replay")
API_KEY_VARS = ("LTAA_ANTHROPIC_API_KEY", "ANTHROPIC_API_KEY")


class ReasonerSettings(Protocol):
    """The fields of app.config.Settings the factory reads (any object with them will do)."""

    anthropic_api_key: SecretStr | None
    anthropic_base_url: str | None
    anthropic_timeout_s: float
    anthropic_max_transport_retries: int
    default_model: str


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


def close_reasoner(reasoner: Reasoner) -> None:
    """Release what a reasoner holds (the anthropic SDK's connection pool); rules has none."""
    close = getattr(reasoner, "close", None)
    if callable(close):
        close()


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
) -> Reasoner:
    """Explicit arguments win over settings, which win over the reasoner's defaults.

    'replay' reads no database: the caller loads the recorded replies of run `replay_of`
    and passes them in `replies`.
    """
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
    if name != "anthropic":
        raise DomainError(
            "reasoner",
            f"unknown reasoner '{name}'; choose one of: {', '.join(REASONERS)}",
            code="unknown_reasoner",
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

    def pick(explicit: Any, setting: str, default: Any) -> Any:
        if explicit is not None:
            return explicit
        value = getattr(settings, setting, None) if settings is not None else None
        return value if value is not None else default

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
    )
