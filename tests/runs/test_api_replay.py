"""Exact replay over HTTP: `reasoner: "replay"` re-runs a finished run from its record.

The original run (anthropic, then openai) goes through the real SDK to the provider's fake
(Messages API, Chat Completions); the fake is stopped before the replay, so any API call
the replay made would fail (and change the verdicts), and the fake must have received
nothing more.
"""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply, context_from_prompt, prompt_of
from tests.fakes.llm_providers import Provider
from tests.fakes.scripted_reasoner import GARBAGE, poor_answer
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until

BASELINE = {"scenario": "baseline", "mode": "balanced"}
ZERO_USAGE = {"llm_calls": 0, "input_tokens": 0, "output_tokens": 0}


def run_to_end(client: TestClient, body: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    created = client.post("/runs", json=body)
    assert created.status_code == 202, created.text
    state = wait_until(client, created.json()["id"], ("completed", "failed", "cancelled"))
    trace = client.get(f"/runs/{state['id']}/trace", params={"include": "prompts"}).json()
    return state, trace


def poor(request: dict[str, Any]) -> Reply:
    return Reply.answer(poor_answer(context_from_prompt(prompt_of(request))))


ATTEMPT_VERDICT = (
    "attempt",
    "tier",
    "parsed",
    "scores",
    "quality",
    "accepted",
    "hard_invalid",
    "feedback",
    "system_prompt",
    "user_prompt",
    "reply",
)
DECISION_VERDICT = (
    "task_index",
    "robot",
    "expected_success",
    "phase",
    "loads_before",
    "loads_after",
    "reasoning",
    "confidence",
    "tradeoff",
    "quality",
    "fallback",
    "failure_log",
    "regret",
)


def verdicts(trace: dict[str, Any]) -> list[dict[str, Any]]:
    return [
        {
            **{k: d[k] for k in DECISION_VERDICT},
            "attempts": [{k: a[k] for k in ATTEMPT_VERDICT} for a in d["attempts"]],
        }
        for d in trace["decisions"]
    ]


def test_replay_of_an_llm_run_with_the_api_stopped_reproduces_it_exactly(
    make_client: ClientFactory, provider: Provider
) -> None:
    api = provider.fake().start()
    # Task 0: a poor answer, fixed at tier 1. Task 1: garbage at every tier, so the
    # fallback decides. Task 2: a 500 the transport gives up on (a failed attempt with no
    # reply), then a good answer. Every later call: a good answer.
    api.script(poor, Reply.from_prompt(), *[Reply.answer(GARBAGE)] * 4, Reply.error(500))
    client = make_client(**provider.settings(api, retries=0))
    try:
        original, first = run_to_end(
            client, {**BASELINE, "reasoner": provider.reasoner, "model": provider.model}
        )
    finally:
        api.stop()
    calls = len(api.requests)
    assert original["status"] == "completed", original
    assert original["usage"]["llm_calls"] == api.answered() == 36 + 1 + 3
    decisions = first["decisions"]
    assert [len(d["attempts"]) for d in decisions[:3]] == [2, 4, 2]
    assert [d["fallback"] for d in decisions[:3]] == [False, True, False]
    assert "gave no reply" in decisions[2]["attempts"][0]["feedback"]

    replay, again = run_to_end(client, {"reasoner": "replay", "replay_of": original["id"]})

    assert len(api.requests) == calls  # the stopped fake saw nothing (and could answer nothing)
    assert replay["status"] == "completed", replay
    assert replay["reasoner"] == "replay" and again["reasoner"] == "replay"
    assert replay["usage"] == ZERO_USAGE
    assert replay["assignments"] == original["assignments"]
    assert replay["metrics"] == original["metrics"] and replay["regret"] == original["regret"]
    assert verdicts(again) == verdicts(first)
    answered = again["decisions"][0]["attempts"][0]
    assert answered["model"] is None and answered["input_tokens"] == 0
    assert answered["replayed_from"] == original["id"]
    assert answered["original_model"] == provider.model
    assert again["events"][0]["detail"]["replay_of"] == original["id"]

    # A replay of the replay is the same record again, and still names the first model.
    twice, thrice = run_to_end(client, {"reasoner": "replay", "replay_of": replay["id"]})
    assert twice["usage"] == ZERO_USAGE and verdicts(thrice) == verdicts(first)
    assert thrice["decisions"][0]["attempts"][0]["original_model"] == provider.model
    assert len(api.requests) == calls


def test_replay_of_a_run_whose_token_budget_switched_it_to_rules_matches_it(
    make_client: ClientFactory,
) -> None:
    api = FakeMessagesAPI().start()
    client = make_client(anthropic_api_key="test-key", anthropic_base_url=api.base_url)
    try:
        original, first = run_to_end(
            client, {**BASELINE, "reasoner": "anthropic", "token_budget": 3000}
        )
    finally:
        api.stop()
    calls = len(api.requests)
    models = [d["attempts"][0]["model"] for d in first["decisions"]]
    assert models[0] is not None and models[-1] is None  # the switch happened mid-run
    assert [e["kind"] for e in first["events"]].count("budget_exhausted") == 1

    replay, again = run_to_end(client, {"reasoner": "replay", "replay_of": original["id"]})
    assert len(api.requests) == calls
    assert replay["assignments"] == original["assignments"]
    assert verdicts(again) == verdicts(first) and replay["usage"] == ZERO_USAGE
    assert [d["attempts"][0]["original_model"] for d in again["decisions"]] == models
    assert "budget_exhausted" not in [e["kind"] for e in again["events"]]


def test_replay_of_a_rules_run_matches_it(client: TestClient) -> None:
    original, first = run_to_end(
        client, {**BASELINE, "mode": "success_focused", "guidance": "optimizer", "seed": 7}
    )
    # Repeating the original's parameters is allowed; the rest is copied.
    replay, again = run_to_end(
        client,
        {"reasoner": "replay", "replay_of": original["id"], "scenario": "baseline", "seed": 7},
    )
    assert replay["status"] == "completed" and replay["mode"] == "success_focused"
    assert replay["assignments"] == original["assignments"]
    assert replay["metrics"] == original["metrics"]  # same seed: same simulated completion
    assert verdicts(again) == verdicts(first)
    assert replay["usage"] == ZERO_USAGE
    assert again["decisions"][0]["attempts"][0]["original_model"] is None


def test_the_synchronous_ltaa_solver_has_no_record_to_replay(client: TestClient) -> None:
    response = client.post(
        "/allocate", json={**BASELINE, "solver": "ltaa", "options": {"reasoner": "replay"}}
    )
    assert response.status_code == 422
    detail = response.json()["detail"][0]
    assert detail["loc"] == ["body", "options", "reasoner"] and "POST /runs" in detail["msg"]


ONE_TASK = {
    "tasks": [{"id": 1, "features": ["heavy"]}],
    "robots": [{"name": "a", "success": {"heavy": 0.9}}, {"name": "b", "success": {"heavy": 0.4}}],
}


def bad_replays(done: str, paused: str) -> list[tuple[dict[str, Any], int, str]]:
    replay = {"reasoner": "replay", "replay_of": done}
    return [
        ({"reasoner": "replay"}, 422, "replay_of"),
        ({**ONE_TASK, "reasoner": "replay"}, 422, "replay_of"),
        ({"reasoner": "replay", "replay_of": "no-such-run"}, 422, "replay_of"),
        ({"reasoner": "replay", "replay_of": paused}, 409, "replay_of"),
        ({**ONE_TASK, "replay_of": done}, 422, "replay_of"),  # default reasoner: rules
        ({**ONE_TASK, "reasoner": "anthropic", "replay_of": done}, 422, "replay_of"),
        ({**replay, "scenario": "baseline"}, 422, "scenario"),
        (
            {**replay, "tasks": [{"id": 2, "features": ["heavy"]}], "robots": ONE_TASK["robots"]},
            422,
            "tasks",
        ),
        ({**replay, "mode": "success_focused"}, 422, "mode"),
        ({**replay, "max_deviation": None}, 422, "max_deviation"),
        ({**replay, "seed": 3}, 422, "seed"),
        ({**replay, "quality_threshold": 0.9}, 422, "quality_threshold"),
        ({**replay, "max_retries": 1}, 422, "max_retries"),
        ({**replay, "guidance": "optimizer"}, 422, "guidance"),
        ({**replay, "model": "claude-test"}, 422, "model"),
        ({**replay, "token_budget": 100}, 422, "token_budget"),
        ({**replay, "review": {"on": ["every_decision"]}}, 422, "review"),
        ({**replay, "review": {}}, 422, "review"),
    ]


def test_bad_replay_requests_are_4xx_naming_the_field_and_write_nothing(
    make_client: ClientFactory,
) -> None:
    # Runs hold before task 1: a one-task run completes, the baseline run stays running.
    client = make_client(test_pause="1:reason:before")
    done, _ = run_to_end(client, {**ONE_TASK, "mode": "balanced"})
    assert done["status"] == "completed", done
    paused = client.post("/runs", json=BASELINE).json()["id"]
    wait_until(client, paused, ("running",))
    before = client.get("/runs").json()

    for body, status, field in bad_replays(done["id"], paused):
        response = client.post("/runs", json=body)
        assert response.status_code == status, (body, response.text)
        detail = response.json()["detail"]
        assert detail[0]["loc"] == ["body", field], (body, detail)
        assert detail[0]["msg"], body
    assert client.get("/runs").json() == before

    unfinished = client.post("/runs", json={"reasoner": "replay", "replay_of": paused})
    assert "running" in unfinished.json()["detail"][0]["msg"]
    assert client.post(f"/runs/{paused}/cancel").status_code == 200
    wait_until(client, paused, ("cancelled",))
    cancelled = client.post("/runs", json={"reasoner": "replay", "replay_of": paused})
    assert cancelled.status_code == 409 and "cancelled" in cancelled.json()["detail"][0]["msg"]

    # A replay's reviews are the original's: it re-applies the recorded resolutions.
    own_review = client.post(
        "/runs",
        json={"reasoner": "replay", "replay_of": done["id"], "review": {"on": ["fallback"]}},
    )
    assert own_review.status_code == 422, own_review.text
    assert "re-applies the original run's review settings" in own_review.json()["detail"][0]["msg"]

    # The original's own values may be repeated (null model/token_budget mean "none").
    same = client.post(
        "/runs",
        json={
            **ONE_TASK,
            "reasoner": "replay",
            "replay_of": done["id"],
            "mode": "balanced",
            "seed": 0,
            "model": None,
            "token_budget": None,
            "review": None,
        },
    )
    assert same.status_code == 202, same.text
    assert (
        wait_until(client, same.json()["id"], ("completed",))["assignments"] == done["assignments"]
    )


def test_a_replay_of_that_no_run_id_can_have_is_a_422_naming_the_field(
    client: TestClient,
) -> None:
    """A NUL character reached the run lookup, where PostgreSQL refuses it (a 500 there)."""
    for replay_of in ("ab\u0000cd", "../runs", "a b"):
        response = client.post("/runs", json={"reasoner": "replay", "replay_of": replay_of})
        assert response.status_code == 422, (replay_of, response.text)
        detail = response.json()["detail"][0]
        assert (detail["loc"], detail["type"]) == (
            ["body", "replay_of"],
            "string_pattern_mismatch",
        ), detail
