"""The give-up rule (docs/reasoners.md#bounded-cost): a run stops asking a model that failed
`after` tasks in a row, the rule decides the rest and the run says so once; through the
graph in memory, and through a durable run whose model server answers 500 to everything."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.graph.pause import PausePoint
from app.graph.state import ModelUse
from app.main import create_app
from app.reasoners.base import ReasonerError
from app.reasoners.give_up import GaveUp, given_up, next_failing
from app.reasoners.rules import compose_answer
from app.reasoners.structured import ReplyFormat
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply
from tests.fakes.llm_providers import Provider
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner
from tests.support.ltaa_support import problem, reply_of, run
from tests.support.polling import wait_until
from tests.support.server import Server


def test_the_row_grows_on_fallbacks_resets_otherwise_and_holds_once_given_up() -> None:
    failing = 0
    for fallback in (True, False, True):
        failing = next_failing(failing, fallback, after=2)
    assert failing == 1 and not given_up(failing, 2)
    failing = next_failing(failing, True, after=2)
    assert given_up(failing, 2)
    assert next_failing(failing, False, after=2) == 2  # held: the rules' decisions succeed
    assert not given_up(100, 0)  # 0 never gives up


@pytest.mark.parametrize("fault", [GARBAGE, ReasonerError("HTTP 500 after 3 retries")])
def test_after_the_setting_the_rule_decides_every_later_task(fault: str | ReasonerError) -> None:
    model = ScriptedReasoner(then=fault)
    use = ModelUse(reply_format=ReplyFormat.JSON_OBJECT, give_up_after=2)
    rec, _ = run(problem(n_tasks=5), model, model_use=use)

    decisions = rec.decisions()
    assert [d.fallback for d in decisions] == [True, True, False, False, False]
    assert [c.task_index for c in model.calls] == [0] * 4 + [1] * 4  # never asked again
    assert rec.gave_up == GaveUp(task_index=2, failing=2, after=2)
    for d in decisions[2:]:
        [attempt] = rec.attempts(d.task_index)
        assert reply_of(attempt).extra == {"reasoner": "rules", "why": "gave_up"}
        assert attempt.accepted and reply_of(attempt).model is None


def test_a_success_between_failures_starts_the_row_again() -> None:
    good = ScriptedReasoner(then=GARBAGE)
    # Task 0 fails (4 attempts), task 1 is answered, tasks 2-3 fail: a row of 2, not 3.
    good.script = [*[GARBAGE] * 4, compose_answer]
    rec, _ = run(problem(n_tasks=4), good, model_use=ModelUse(give_up_after=3))
    assert [d.fallback for d in rec.decisions()] == [True, False, True, True]
    assert rec.gave_up is None and len(good.calls) == 13


def test_never_with_zero() -> None:
    model = ScriptedReasoner(then=GARBAGE)
    rec, _ = run(problem(n_tasks=4), model, model_use=ModelUse(give_up_after=0))
    assert all(d.fallback for d in rec.decisions()) and len(model.calls) == 16
    assert rec.gave_up is None


# ------------------------------------------------------------- a durable run, a dead server


@pytest.fixture
def failing_server(provider: Provider) -> Iterator[FakeMessagesAPI]:
    """A model server that answers HTTP 500 to every request."""
    with provider.fake(default=lambda request: Reply.error(500, retry_after=0.01)) as api:
        yield api


def test_a_server_that_answers_500_to_everything_costs_the_bound_then_the_rule(
    settings: Settings, provider: Provider, failing_server: FakeMessagesAPI
) -> None:
    update = {**provider.settings(failing_server, retries=1), "llm_give_up_after": 2}
    with TestClient(create_app(settings.model_copy(update=update))) as client:
        baseline = next(s for s in client.get("/scenarios").json() if s["name"] == "baseline")
        body = {
            "tasks": baseline["tasks"][:6],
            "robots": baseline["robots"],
            "reasoner": provider.reasoner,
            "model": provider.model,
        }
        created = client.post("/runs", json=body)
        assert created.status_code == 202, created.text
        run_id = created.json()["id"]
        state = wait_until(client, run_id)
        trace = client.get(f"/runs/{run_id}/trace").json()
        metrics = client.get("/metrics").text
        page = client.get(f"/console/runs/{run_id}")

    assert state["status"] == "completed", state
    # Two tasks of four attempts, each tried twice by the SDK, and not one request more.
    assert len(failing_server.requests) == 2 * 4 * 2
    [event] = [e for e in trace["events"] if e["kind"] == "llm_gave_up"]
    assert event["detail"] == {"task_index": 2, "failing": 2, "after": 2}
    decisions = trace["decisions"]
    assert [d["fallback"] for d in decisions] == [True, True, False, False, False, False]
    for d in decisions[2:]:
        assert [(a["reasoner"], a["why"]) for a in d["attempts"]] == [("rules", "gave_up")]
    assert "ltaa_llm_gave_up_total 1.0" in metrics
    assert page.status_code == 200 and 'id="llm-gave-up"' in page.text


# ------------------------------------------------------------------ across a SIGKILL, twice


def _held(server: Server, run_id: str, at: PausePoint) -> list[str]:
    server.wait_for_log(at.message())
    with server.client() as c:
        kinds = [e["kind"] for e in c.get(f"/runs/{run_id}/trace").json()["events"]]
    server.kill()
    return kinds


@pytest.mark.e2e
def test_the_row_survives_a_sigkill_and_the_switch_is_told_once(tmp_path: Path) -> None:
    """Killed at task 2 before its reason node (the row is 2, nothing switched yet), then
    at task 3 (switched at 2): the model is never asked after the row reached the setting,
    the event is written once, and the record is an uninterrupted run's."""
    with FakeMessagesAPI(default=lambda request: Reply.answer(GARBAGE)) as api:
        env = {
            "LTAA_ANTHROPIC_API_KEY": "test-key",
            "LTAA_ANTHROPIC_BASE_URL": api.base_url,
            "LTAA_LLM_GIVE_UP_AFTER": "2",
        }
        data = tmp_path / "data"
        server = Server(data, env=env).start()
        try:
            with server.client() as c:
                baseline = next(s for s in c.get("/scenarios").json() if s["name"] == "baseline")
            body = {
                "tasks": baseline["tasks"][:5],
                "robots": baseline["robots"],
                "reasoner": "anthropic",
                "model": "claude-test",
            }
            reference = _record(*_finished(server, _submit(server, body)))
        finally:
            server.stop()
        asked_by_reference = len(api.requests)

        before, after = PausePoint(2, "reason", after=False), PausePoint(3, "reason", after=False)
        first = Server(data, env=env).start(pause=before)
        run_id = _submit(first, body)
        assert "llm_gave_up" not in _held(first, run_id, before)
        second = Server(data, env=env).start(pause=after)
        assert _held(second, run_id, after).count("llm_gave_up") == 1
        last = Server(data, env=env).start()
        try:
            state, trace = _finished(last, run_id)
        finally:
            last.stop()

    assert state["resumes"] == 2
    assert _record(state, trace) == reference
    # Two failed tasks of four attempts each, for each run: nothing asked again.
    assert asked_by_reference == 8 and len(api.requests) == 16


def _submit(server: Server, body: dict[str, Any]) -> str:
    with server.client() as c:
        response = c.post("/runs", json=body)
    assert response.status_code == 202, response.text
    return str(response.json()["id"])


def _finished(server: Server, run_id: str) -> tuple[dict[str, Any], dict[str, Any]]:
    state = server.wait_for(run_id, lambda s: s["status"] in ("completed", "failed"))
    assert state["status"] == "completed", state
    with server.client() as c:
        return state, c.get(f"/runs/{run_id}/trace").json()


def _record(state: dict[str, Any], trace: dict[str, Any]) -> dict[str, Any]:
    return {
        "events": [e["detail"] for e in trace["events"] if e["kind"] == "llm_gave_up"],
        "attempts": [
            [(a["reasoner"], a["why"], a["accepted"], a["tier"]) for a in d["attempts"]]
            for d in trace["decisions"]
        ],
        "assignments": [(a["task_id"], a["robot"]) for a in state["assignments"]],
        "usage": state["usage"],
    }
