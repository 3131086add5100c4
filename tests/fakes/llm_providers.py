"""The LLM providers a test suite runs over: each reasoner with its loopback fake and the
settings that point the server at that fake.

    @pytest.fixture(params=PROVIDERS.values(), ids=PROVIDERS.keys())
    def provider(request): return request.param
"""

from __future__ import annotations

from dataclasses import dataclass
from typing import Any

from pydantic import SecretStr

from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI
from tests.fakes.fake_messages_api import FakeMessagesAPI


@dataclass(frozen=True)
class Provider:
    reasoner: str  # the reasoner name runs send
    fake: type[FakeMessagesAPI]
    model: str  # the model runs name (the fakes echo it)
    # The setting a server without this provider's configuration names in its error.
    missing_setting: str

    def settings(
        self, api: FakeMessagesAPI, *, retries: int | None = None, timeout_s: float | None = None
    ) -> dict[str, Any]:
        """Settings fields (for Settings.model_copy(update=...)) reaching `api`."""
        prefix = self.reasoner
        update: dict[str, Any] = {f"{prefix}_base_url": api.base_url}
        if self.reasoner == "anthropic":
            update["anthropic_api_key"] = SecretStr("test-key")
        else:
            update["openai_api_key"] = SecretStr("test-key")
            update["openai_model"] = self.model
        if retries is not None:
            update[f"{prefix}_max_transport_retries"] = retries
        if timeout_s is not None:
            update[f"{prefix}_timeout_s"] = timeout_s
        return update

    def env(self, api: FakeMessagesAPI, *, retries: int | None = None) -> dict[str, str]:
        """The same, as LTAA_* environment variables for a server subprocess."""
        out: dict[str, str] = {}
        for field, value in self.settings(api, retries=retries).items():
            raw = value.get_secret_value() if isinstance(value, SecretStr) else str(value)
            out[f"LTAA_{field.upper()}"] = raw
        return out


PROVIDERS = {
    "anthropic": Provider("anthropic", FakeMessagesAPI, "claude-test", "ANTHROPIC_API_KEY"),
    "openai": Provider("openai", FakeChatCompletionsAPI, "local-test", "LTAA_OPENAI_BASE_URL"),
}
