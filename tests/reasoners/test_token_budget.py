"""The per-run token budget: once a run's LLM calls have spent it, the remaining tasks go
to the offline rules reasoner, recorded once as a `budget_exhausted` event.

The wrapper alone (with a scripted reasoner), then durable runs on the real SDK against
the fake Messages API, with the budget from the request and from the server's setting.
(Across a SIGKILL and a restart: tests/reasoners/test_token_budget_resume.py.)
"""

from __future__ import annotations

from collections.abc import Iterator
from itertools import accumulate
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr
from sqlalchemy.orm import Session

from app.config import Settings
from app.main import create_app
from app.reasoners.base import ReasonerError
from app.reasoners.budget import BUDGET_EXHAUSTED, BudgetExhausted, TokenBudgetReasoner
from app.runs.recorder import LeaseLost, with_token_budget
from app.store import repository as repo
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from tests.fakes.fake_messages_api import FakeMessagesAPI
from tests.fakes.scripted_reasoner import GARBAGE, ScriptedReasoner
from tests.support.factories import run_row
from tests.support.ltaa_support import problem, reply_of, run
from tests.support.polling import wait_until

N_TASKS = 6

# ------------------------------------------------------------------ the wrapper alone


def test_the_switch_comes_once_the_budget_is_reached_and_is_told_once() -> None:
    told: list[BudgetExhausted] = []
    llm = ScriptedReasoner(tokens=(100, 50))  # 150 tokens a call
    budgeted = TokenBudgetReasoner(llm, budget=300, spent=0, on_exhausted=told.append)
    rec, _ = run(problem(n_tasks=4), budgeted)

    # Tasks 0 and 1 spend 300 = the budget: tasks 2 and 3 are the rules reasoner's.
    assert [c.task_index for c in llm.calls] == [0, 1]
    assert [reply_of(a).model for a in rec.attempts()] == ["scripted", "scripted", None, None]
    assert told == [BudgetExhausted(task_index=2, tokens_spent=300, budget=300)]
    assert all(a.accepted for a in rec.attempts())
    assert reply_of(rec.attempts()[2]).extra == {"reasoner": "rules", "why": "budget_exhausted"}
    assert reply_of(rec.attempts()[0]).extra["reasoner"] == "scripted"


def test_a_retry_after_the_budget_is_spent_goes_to_the_rules_reasoner() -> None:
    told: list[BudgetExhausted] = []
    # Task 0: a useless answer that spends the whole budget; its tier-1 retry is rules.
    llm = ScriptedReasoner([GARBAGE], tokens=(200, 100))
    budgeted = TokenBudgetReasoner(llm, budget=250, spent=0, on_exhausted=told.append)
    rec, _ = run(problem(n_tasks=2), budgeted)
    first, second = rec.attempts(0)
    assert reply_of(first).model == "scripted" and not first.accepted
    assert reply_of(second).model is None and second.accepted and second.tier == 1
    assert len(llm.calls) == 1 and told == [BudgetExhausted(0, 300, 250)]


def test_spent_tokens_are_seeded_and_failed_calls_cost_nothing() -> None:
    told: list[BudgetExhausted] = []
    llm = ScriptedReasoner([ReasonerError("HTTP 529 after 3 transport retries")], tokens=(100, 50))
    # 200 already spent before a restart: one call (failed, free), one paid, then rules.
    budgeted = TokenBudgetReasoner(llm, budget=300, spent=200, on_exhausted=told.append)
    rec, _ = run(problem(n_tasks=2), budgeted)
    assert [reply_of(a).model for a in rec.attempts()] == [None, "scripted", None]
    assert budgeted.spent == 350 and told == [BudgetExhausted(1, 350, 300)]

    seeded = TokenBudgetReasoner(
        ScriptedReasoner(), budget=300, spent=300, on_exhausted=told.append
    )
    rec, _ = run(problem(n_tasks=1), seeded)
    assert reply_of(rec.attempts()[0]).model is None and told[-1].task_index == 0


# ------------------------------------------------------------------ durable runs


@pytest.fixture
def api() -> Iterator[FakeMessagesAPI]:
    with FakeMessagesAPI() as server:
        yield server


def client_for(settings: Settings, api: FakeMessagesAPI, **overrides: Any) -> TestClient:
    return TestClient(
        create_app(
            settings.model_copy(
                update={
                    "anthropic_api_key": SecretStr("test-key"),
                    "anthropic_base_url": api.base_url,
                    **overrides,
                }
            )
        )
    )


def llm_run(client: TestClient, **extra: Any) -> tuple[dict[str, Any], dict[str, Any]]:
    baseline = next(s for s in client.get("/scenarios").json() if s["name"] == "baseline")
    body = {
        "tasks": baseline["tasks"][:N_TASKS],
        "robots": baseline["robots"],
        "reasoner": "anthropic",
        "model": "claude-test",
        **extra,
    }
    created = client.post("/runs", json=body)
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    state = wait_until(client, run_id)
    assert state["status"] == "completed", state
    return state, client.get(f"/runs/{run_id}/trace", params={"include": "prompts"}).json()


def budget_events(trace: dict[str, Any]) -> list[dict[str, Any]]:
    return [e["detail"] for e in trace["events"] if e["kind"] == "budget_exhausted"]


def spent_before_each_task(api: FakeMessagesAPI) -> list[int]:
    """From the fake's own accounting of a run answered first time at every task:
    element k is what tasks 0..k-1 cost."""
    calls = [s.input_tokens + s.output_tokens for s in api.served]
    return [0, *accumulate(calls)]


def test_a_run_switches_to_rules_at_the_task_where_its_budget_is_reached(
    settings: Settings, api: FakeMessagesAPI
) -> None:
    with client_for(settings, api) as client:
        unlimited_state, unlimited = llm_run(client)
        spent_before = spent_before_each_task(api)
        assert budget_events(unlimited) == [] and api.answered() == N_TASKS
        api.served.clear()

        # Reached exactly before task 2 (">= budget"): tasks 2.. are the rules reasoner's.
        exact_state, exact = llm_run(client, token_budget=spent_before[2])
        assert api.answered() == 2
        # One token more: task 2 still calls Claude and overshoots by less than one call.
        over_state, over = llm_run(client, token_budget=spent_before[2] + 1)
        assert api.answered() == 2 + 3

    for state, trace, switch in ((exact_state, exact, 2), (over_state, over, 3)):
        budget = spent_before[2] + (switch == 3)
        assert budget_events(trace) == [
            {"task_index": switch, "tokens_spent": spent_before[switch], "budget": budget}
        ]
        models = [[a["model"] for a in d["attempts"]] for d in trace["decisions"]]
        assert models == [["claude-test"]] * switch + [[None]] * (N_TASKS - switch)
        for decision in trace["decisions"][switch:]:
            [attempt] = decision["attempts"]
            assert attempt["accepted"] and attempt["reply"].startswith("**Decision**")
            assert "Rule-based choice" in attempt["reply"] and not decision["fallback"]
        usage = state["usage"]
        spent = usage["input_tokens"] + usage["output_tokens"]
        last_call = spent_before[switch] - spent_before[switch - 1]
        assert spent == spent_before[switch] and budget <= spent <= budget + last_call
        assert usage["llm_calls"] == switch
        # The fake answers as the rules do, so the allocation is the unlimited run's.
        assert state["assignments"] == unlimited_state["assignments"]
        kinds = [e["kind"] for e in trace["events"]]
        assert kinds.index("started") < kinds.index("budget_exhausted") < kinds.index("completed")


def test_the_server_setting_is_the_default_budget_and_a_request_overrides_it(
    settings: Settings, api: FakeMessagesAPI, monkeypatch: pytest.MonkeyPatch
) -> None:
    monkeypatch.setenv("LTAA_RUN_TOKEN_BUDGET", "1")
    assert Settings().run_token_budget == 1
    with client_for(settings, api, run_token_budget=1) as client:
        _, by_setting = llm_run(client)
        _, by_request = llm_run(client, token_budget=10**9)
        refused = client.post("/runs", json={"scenario": "baseline", "token_budget": 0})

    # A budget of 1: the first call is allowed (nothing spent yet), everything after is rules.
    [event] = budget_events(by_setting)
    assert event["task_index"] == 1 and event["budget"] == 1 and event["tokens_spent"] > 1
    assert budget_events(by_request) == []
    assert all(a["model"] == "claude-test" for d in by_request["decisions"] for a in d["attempts"])
    assert refused.status_code == 422
    assert refused.json()["detail"][0]["loc"] == ["body", "token_budget"]


def test_a_process_that_lost_the_run_writes_no_budget_event(tmp_path: Path) -> None:
    """The switch's event goes through the recorder's fence (PostgreSQL leases): a process
    whose lease passed to another stops instead of writing it."""
    url = f"sqlite:///{tmp_path / 'ltaa.db'}"
    upgrade_head(url)
    engine = make_engine(url)
    sessions = make_session_factory(engine)
    with transaction(sessions) as session:
        session.add(run_row("r1", "running", reasoner="anthropic", n_tasks=2, n_robots=3))

    def lease_gone(session: Session) -> None:
        raise LeaseLost("r1")

    budgeted = with_token_budget(
        ScriptedReasoner(tokens=(100, 50)),
        run_id="r1",
        budget=100,
        sessions=sessions,
        fence=lease_gone,
    )
    try:
        with pytest.raises(LeaseLost):
            run(problem(n_tasks=2), budgeted)
        with sessions() as session:
            assert not repo.has_event(session=session, run_id="r1", kind=BUDGET_EXHAUSTED)
    finally:
        engine.dispose()
