"""A durable run with each LLM reasoner (anthropic, openai): the real SDK, the real server,
the provider's fake on loopback failing the way real networks do."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI
from tests.fakes.fake_messages_api import Reply
from tests.fakes.llm_providers import Provider
from tests.fakes.scripted_reasoner import GARBAGE
from tests.fakes.structured_replies import as_structured
from tests.support.server import Server

pytestmark = pytest.mark.e2e


def test_a_run_through_transport_faults_and_a_poor_answer(
    tmp_path: Path, provider: Provider
) -> None:
    with provider.fake() as api:
        # Task 0: 429, then 500 (both retried by the SDK), then an unusable answer
        # (rejected by validation, fixed at tier 1). Every later call is a good answer.
        api.script(Reply.error(429), Reply.error(500), Reply.answer(GARBAGE))
        server = Server(tmp_path / "data", env=provider.env(api)).start()
        try:
            with server.client() as c:
                created = c.post(
                    "/runs",
                    json={
                        "scenario": "baseline",
                        "mode": "balanced",
                        "reasoner": provider.reasoner,
                        "model": provider.model,
                    },
                )
                assert created.status_code == 202, created.text
                run_id = created.json()["id"]
            state: dict[str, Any] = server.wait_for(
                run_id, lambda s: s["status"] in ("completed", "failed"), timeout=120
            )
            with server.client() as c:
                trace = c.get(f"/runs/{run_id}/trace", params={"include": "prompts"}).json()
        finally:
            server.stop()

        assert state["status"] == "completed", state
        assert state["usage"]["llm_calls"] == api.answered() == 37
        assert (state["usage"]["input_tokens"], state["usage"]["output_tokens"]) == api.tokens()
        first = trace["decisions"][0]
        assert [a["tier"] for a in first["attempts"]] == [0, 1]
        rejected, fixed = first["attempts"]
        assert rejected["accepted"] is False and rejected["transport_retries"] == 2
        # GARBAGE as a constrained server writes it in the run's structured format
        # (docs/reasoners.md#structured-replies): an object with none of its required fields.
        assert rejected["feedback"] and rejected["reply"] == as_structured(GARBAGE, {}) == "{}"
        assert "field `the reply`: 'decision' is a required property" in rejected["hard_invalid"]
        assert fixed["accepted"] is True and fixed["model"] == provider.model
        assert all(not d["fallback"] for d in trace["decisions"])
        assert {r["model"] for r in api.requests} == {provider.model}


@pytest.fixture(scope="module")
def unconfigured(
    tmp_path_factory: pytest.TempPathFactory,
) -> Iterator[tuple[Server, FakeChatCompletionsAPI]]:
    """One server with no provider configured, for both providers' refusals (each refused
    run writes nothing, so neither check sees the other's): a server start is 2-3 CPU-s.
    The SDKs' own variables point at a live decoy: the openai one must never be used."""
    with FakeChatCompletionsAPI() as decoy:
        env = {"OPENAI_BASE_URL": decoy.base_url, "OPENAI_API_KEY": "sk-from-the-environment"}
        server = Server(tmp_path_factory.mktemp("unconfigured") / "data", env=env).start()
        try:
            yield server, decoy
        finally:
            server.stop()


def test_an_unconfigured_provider_is_a_422_naming_the_setting(
    unconfigured: tuple[Server, FakeChatCompletionsAPI], provider: Provider
) -> None:
    server, decoy = unconfigured
    with server.client() as c:
        response = c.post("/runs", json={"scenario": "baseline", "reasoner": provider.reasoner})
        assert response.status_code == 422
        assert response.json()["detail"][0]["loc"] == ["body", "reasoner"]
        assert provider.missing_setting in response.json()["detail"][0]["msg"]
        assert c.get("/runs").json() == []
    assert decoy.requests == []
