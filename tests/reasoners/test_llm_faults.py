"""LLM faults through durable runs, for every LLM provider: the real SDK (anthropic, openai)
against its loopback fake (Messages API, Chat Completions), the real worker, SQLite and
trace endpoint.

Every fault must end in one of three ways, each visible in GET /runs/{id}/trace:
a transport retry (the SDK tried again: the attempt's `transport_retries`), a validation
retry (a failed attempt with `hard_invalid` and `feedback`, then the next tier), or the
rules fallback (`fallback` with a `failure_log`). No run fails because of the LLM.
"""

from __future__ import annotations

import itertools
from collections.abc import Callable, Iterator
from dataclasses import dataclass
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.main import create_app
from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply, answer_from_prompt, prompt_of
from tests.fakes.llm_providers import Provider
from tests.support.polling import wait_until

TRANSPORT_RETRIES = 2  # the SDK's max_retries in these tests
TIMEOUT_S = 2.0  # the client's timeout; a "slow" reply takes longer


def unknown_robot(request: dict[str, Any]) -> Reply:
    """A well-formed answer in every section, but naming a robot the instance lacks."""
    _, rest = answer_from_prompt(prompt_of(request)).split("\n", 1)
    return Reply.answer("**Decision**: Flying Robot\n" + rest)


@pytest.fixture
def api(provider: Provider) -> Iterator[FakeMessagesAPI]:
    with provider.fake() as server:
        yield server


@pytest.fixture
def client(settings: Settings, api: FakeMessagesAPI, provider: Provider) -> Iterator[TestClient]:
    update = provider.settings(api, retries=TRANSPORT_RETRIES, timeout_s=TIMEOUT_S)
    app = create_app(settings.model_copy(update=update))
    with TestClient(app) as c:
        c.provider = provider  # type: ignore[attr-defined]
        yield c


def llm_run(client: TestClient, n_tasks: int = 2) -> tuple[dict[str, Any], dict[str, Any]]:
    """A run of the baseline's first tasks on the provider's model; its final state and its
    trace."""
    provider: Provider = client.provider  # type: ignore[attr-defined]
    baseline = next(s for s in client.get("/scenarios").json() if s["name"] == "baseline")
    body = {
        "tasks": baseline["tasks"][:n_tasks],
        "robots": baseline["robots"],
        "reasoner": provider.reasoner,
        "model": provider.model,
    }
    created = client.post("/runs", json=body)
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    state = wait_until(client, run_id)
    trace = client.get(f"/runs/{run_id}/trace").json()
    return state, trace


def assert_completed(state: dict[str, Any], trace: dict[str, Any], n_tasks: int = 2) -> None:
    assert state["status"] == "completed" and state["error"] is None, state
    kinds = [e["kind"] for e in trace["events"]]
    assert kinds[-1] == "completed" and "failed" not in kinds
    assert [d["task_index"] for d in trace["decisions"]] == list(range(n_tasks))


# ------------------------------------------------------------- transport retries (SDK)


@dataclass(frozen=True)
class TransportFault:
    reply: Reply
    served_first: int  # the status the fake recorded for the failed try
    min_wait_s: float = 0.0  # the SDK waited at least this before trying again


TRANSPORT_FAULTS = {
    "529 overloaded": TransportFault(Reply.overloaded(retry_after=0.05), 529),
    # retry-after 1 s against the SDK's own first backoff of at most 0.5 s: a wait of 1 s
    # or more shows the header was honoured.
    "429 retry-after": TransportFault(Reply.error(429, retry_after=1), 429, min_wait_s=1.0),
    "500 (SDK backoff)": TransportFault(Reply.error(500, retry_after=None), 500),
    "timeout": TransportFault(Reply.slow(TIMEOUT_S + 1.5), 200, min_wait_s=TIMEOUT_S),
    "connection dropped mid-body": TransportFault(Reply.dropped(after=40), 200),
}


@pytest.mark.parametrize("fault", TRANSPORT_FAULTS.values(), ids=TRANSPORT_FAULTS.keys())
def test_a_transport_fault_is_retried_by_the_sdk(
    client: TestClient, api: FakeMessagesAPI, provider: Provider, fault: TransportFault
) -> None:
    api.script(fault.reply)
    state, trace = llm_run(client)
    assert_completed(state, trace)

    [attempt] = trace["decisions"][0]["attempts"]
    assert attempt["transport_retries"] == 1 and attempt["accepted"] is True
    assert attempt["model"] == provider.model and attempt["hard_invalid"] is None
    assert not trace["decisions"][0]["fallback"] and trace["decisions"][0]["failure_log"] == []
    first, second = api.requests[:2]
    assert (
        first["_headers"]["x-stainless-retry-count"],
        second["_headers"]["x-stainless-retry-count"],
    ) == ("0", "1")
    assert second["_received_at"] - first["_received_at"] >= fault.min_wait_s
    assert api.served[0].status == fault.served_first
    # Only the delivered answer is billed, and the run counts exactly that.
    assert state["usage"]["llm_calls"] == api.answered() == 2
    assert (state["usage"]["input_tokens"], state["usage"]["output_tokens"]) == api.tokens()


def test_overloaded_is_served_in_the_messages_api_error_shape() -> None:
    import httpx

    with FakeMessagesAPI() as api:
        api.script(Reply.overloaded(retry_after=3))
        response = httpx.post(f"{api.base_url}/v1/messages", json={"messages": []})
    assert response.status_code == 529 and response.headers["retry-after"] == "3"
    body = response.json()
    assert body["type"] == "error" and body["request_id"].startswith("req_")
    assert body["error"] == {"type": "overloaded_error", "message": "Overloaded"}


def test_a_rate_limit_is_served_in_the_chat_completions_error_shape() -> None:
    import httpx

    from tests.fakes.fake_chat_completions_api import FakeChatCompletionsAPI

    with FakeChatCompletionsAPI() as api:
        api.script(Reply.error(429, retry_after=3))
        response = httpx.post(f"{api.base_url}/chat/completions", json={"messages": []})
    assert response.status_code == 429 and response.headers["retry-after"] == "3"
    assert response.json()["error"]["type"] == "rate_limit_exceeded"


# ------------------------------------------------------------- validation retries

VALIDATION_FAULTS: dict[str, tuple[Reply | Callable[[dict[str, Any]], Reply], str]] = {
    "empty body": (Reply.empty(), "unreadable reply (HTTP 200, 0 bytes, application/json)"),
    "truncated JSON": (Reply.truncated(keep=60), "unreadable reply (HTTP 200, 60 bytes"),
    "non-JSON garbage": (Reply.garbage(), "text/html): body: Invalid JSON"),
    "JSON of another shape": (Reply(body=b'{"ok": true}'), "id: Field required"),
    # Structured replies (the default): the robot is read against the decision's schema.
    "unknown robot": (unknown_robot, "field `decision`: 'Flying Robot' is not one of"),
}


@pytest.mark.parametrize(("fault", "why"), VALIDATION_FAULTS.values(), ids=VALIDATION_FAULTS.keys())
def test_a_bad_reply_is_a_failed_attempt_retried_at_the_next_tier(
    client: TestClient, api: FakeMessagesAPI, provider: Provider, fault: Reply, why: str
) -> None:
    api.script(fault)
    state, trace = llm_run(client)
    assert_completed(state, trace)

    decision = trace["decisions"][0]
    failed, fixed = decision["attempts"]
    assert failed["accepted"] is False and failed["quality"] == 0.0
    assert why in failed["hard_invalid"]
    assert failed["feedback"].startswith("Hard invalid (Q=0)") and why in failed["feedback"]
    assert failed["transport_retries"] == 0  # the SDK had nothing to retry: a 200 came back
    assert fixed["tier"] == 1 and fixed["accepted"] is True and fixed["model"] == provider.model
    assert not decision["fallback"]
    assert len(decision["failure_log"]) == 1 and why in decision["failure_log"][0]
    # The retry prompt carried the feedback to the model.
    assert why in prompt_of(api.requests[1])
    # An unreadable body names no model and costs nothing; the unknown robot was an answer.
    answered = fault is unknown_robot
    assert (failed["model"] is not None) is answered
    assert state["usage"]["llm_calls"] == api.answered() == 2 + answered
    assert (state["usage"]["input_tokens"], state["usage"]["output_tokens"]) == api.tokens()


# ------------------------------------------------------------- the fallback


def test_a_transport_that_gives_up_at_every_tier_ends_in_the_fallback(
    client: TestClient, api: FakeMessagesAPI
) -> None:
    tries = 4 * (1 + TRANSPORT_RETRIES)  # max_retries 3: four attempts, each tried thrice
    api.script(*[Reply.overloaded(retry_after=0.01)] * tries)
    state, trace = llm_run(client)
    assert_completed(state, trace)

    decision = trace["decisions"][0]
    assert decision["fallback"] is True and len(decision["failure_log"]) == 4
    assert [a["tier"] for a in decision["attempts"]] == [0, 1, 2, 3]
    for attempt in decision["attempts"]:
        assert attempt["transport_retries"] == TRANSPORT_RETRIES and attempt["model"] is None
        assert f"HTTP 529 after {TRANSPORT_RETRIES} transport retries" in attempt["hard_invalid"]
    assert "Overloaded" in decision["failure_log"][0]
    assert [s.status for s in api.served[:tries]] == [529] * tries
    assert not trace["decisions"][1]["fallback"]  # the API recovered for the next task


def test_a_run_whose_every_call_fails_completes_on_fallbacks(
    settings: Settings, provider: Provider
) -> None:
    faults: Iterator[Callable[[], Reply]] = itertools.cycle(
        [
            Reply.empty,
            Reply.truncated,
            Reply.garbage,
            lambda: Reply(body=b"{}"),
            lambda: Reply.overloaded(retry_after=0.01),
            lambda: Reply.error(500, retry_after=0.01),
            Reply.dropped,
        ]
    )
    with provider.fake(default=lambda request: next(faults)()) as api:
        # Never given up (docs/reasoners.md#bounded-cost), so every task meets every fault.
        update = {**provider.settings(api, retries=1), "llm_give_up_after": 0}
        with TestClient(create_app(settings.model_copy(update=update))) as client:
            client.provider = provider  # type: ignore[attr-defined]
            state, trace = llm_run(client, n_tasks=4)
        statuses = {s.status for s in api.served}

    assert_completed(state, trace, n_tasks=4)
    assert statuses == {200, 500, 529}
    assert state["usage"]["llm_calls"] == 0 and state["usage"]["input_tokens"] == 0
    for decision in trace["decisions"]:
        assert decision["fallback"] is True and len(decision["failure_log"]) == 4
        assert all(
            a["hard_invalid"].startswith("the reasoner gave no reply") for a in decision["attempts"]
        )
        # The fallback is the rules reasoner's choice, validated like any answer.
        assert decision["quality"] >= 0.9 and "Rule-based choice" in decision["reasoning"]


def test_a_resume_without_the_configuration_fails_saying_what_to_set(
    settings: Settings, provider: Provider
) -> None:
    with provider.fake() as api:
        keyed = settings.model_copy(
            update={**provider.settings(api), "test_pause": f"{1}:reason:before"}
        )
        with TestClient(create_app(keyed)) as first:
            baseline = next(s for s in first.get("/scenarios").json() if s["name"] == "baseline")
            run_id = first.post(
                "/runs",
                json={
                    "tasks": baseline["tasks"][:2],
                    "robots": baseline["robots"],
                    "reasoner": provider.reasoner,
                    "model": provider.model,
                },
            ).json()["id"]
            wait_until(first, run_id, ("running",))
    # The key (the server's URL) is gone when the server starts again and resumes the
    # interrupted run.
    with TestClient(create_app(settings)) as second:
        state = wait_until(second, run_id, ("failed", "completed"))
    assert state["status"] == "failed"
    assert provider.missing_setting in state["error"]
    assert "internal error" not in state["error"]
