"""A request naming the `openai` reasoner on a server without its settings is a 422 that
says which LTAA_ setting to set, whatever OPENAI_* variables the environment holds: the
SDK's own fallbacks (api.openai.com, OPENAI_BASE_URL) never receive a request."""

from __future__ import annotations

from collections.abc import Iterator

import pytest
from fastapi.testclient import TestClient

from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI
from tests.support.clients import ClientFactory

BASELINE_START = {"scenario": "baseline", "mode": "balanced"}


@pytest.fixture
def decoy(monkeypatch: pytest.MonkeyPatch) -> Iterator[FakeChatCompletionsAPI]:
    """A server the SDK's environment points at, which must never be called."""
    with FakeChatCompletionsAPI() as server:
        monkeypatch.setenv("OPENAI_BASE_URL", server.base_url)
        monkeypatch.setenv("OPENAI_API_KEY", "sk-from-the-environment")
        for name in ("LTAA_OPENAI_BASE_URL", "LTAA_OPENAI_MODEL", "LTAA_OPENAI_API_KEY"):
            monkeypatch.delenv(name, raising=False)
        yield server


def only_error(response: object, loc: list[str]) -> str:
    assert getattr(response, "status_code") == 422, getattr(response, "text")  # noqa: B009
    [item] = response.json()["detail"]  # type: ignore[attr-defined]
    assert item["loc"] == loc and item["type"] == "missing_setting", item
    return str(item["msg"])


@pytest.mark.parametrize(
    ("configured", "missing"),
    [
        ({}, "LTAA_OPENAI_BASE_URL"),
        ({"openai_model": "some-model"}, "LTAA_OPENAI_BASE_URL"),
        ({"openai_base_url": "http://127.0.0.1:9/v1"}, "LTAA_OPENAI_MODEL"),
    ],
    ids=["nothing", "no base URL", "no model"],
)
def test_a_run_is_a_422_naming_the_missing_setting(
    make_client: ClientFactory,
    decoy: FakeChatCompletionsAPI,
    configured: dict[str, str],
    missing: str,
) -> None:
    client = make_client(**configured)
    response = client.post("/runs", json={**BASELINE_START, "reasoner": "openai"})
    assert missing in only_error(response, ["body", "reasoner"])
    assert client.get("/runs").json() == []  # nothing was written
    assert decoy.requests == []


def test_allocate_is_a_422_naming_the_missing_setting(
    client: TestClient, decoy: FakeChatCompletionsAPI
) -> None:
    response = client.post(
        "/allocate",
        json={**BASELINE_START, "solver": "ltaa", "options": {"reasoner": "openai"}},
    )
    assert "LTAA_OPENAI_BASE_URL" in only_error(response, ["body", "options", "reasoner"])
    assert decoy.requests == []
