"""A durable run with the anthropic reasoner: the real SDK, the real server, a fake
Messages API on loopback that fails the way real networks do."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest

from tests.e2e.server import Server
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply
from tests.fakes.scripted_reasoner import GARBAGE

pytestmark = pytest.mark.e2e


def test_anthropic_run_through_transport_faults_and_a_poor_answer(tmp_path: Path) -> None:
    with FakeMessagesAPI() as api:
        # Task 0: 429, then 500 (both retried by the SDK), then an unusable answer
        # (rejected by validation, fixed at tier 1). Every later call is a good answer.
        api.script(Reply.error(429), Reply.error(500), Reply.answer(GARBAGE))
        server = Server(
            tmp_path / "data",
            env={
                "LTAA_ANTHROPIC_API_KEY": "test-key",
                "LTAA_ANTHROPIC_BASE_URL": api.base_url,
            },
        ).start()
        try:
            with server.client() as c:
                created = c.post(
                    "/runs",
                    json={
                        "scenario": "baseline",
                        "mode": "balanced",
                        "reasoner": "anthropic",
                        "model": "claude-test",
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
        assert rejected["feedback"] and rejected["reply"] == GARBAGE
        assert fixed["accepted"] is True and fixed["model"] == "claude-test"
        assert all(not d["fallback"] for d in trace["decisions"])
        assert {r["model"] for r in api.requests} == {"claude-test"}


def test_anthropic_without_a_key_is_a_422(tmp_path: Path) -> None:
    server = Server(tmp_path / "data").start()
    try:
        with server.client() as c:
            response = c.post("/runs", json={"scenario": "baseline", "reasoner": "anthropic"})
            assert response.status_code == 422
            assert response.json()["detail"][0]["loc"] == ["body", "reasoner"]
            assert "ANTHROPIC_API_KEY" in response.json()["detail"][0]["msg"]
            assert c.get("/runs").json() == []
    finally:
        server.stop()
