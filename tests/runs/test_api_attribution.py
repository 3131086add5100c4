"""Every attempt in the trace and in the JSON-lines export names the reasoner that wrote
its reply, and `why` where the rules reasoner stood in for the run's LLM; every decision
names whose answer it took (the rules fallback: why 'fallback')."""

from __future__ import annotations

import json
from typing import Any

from fastapi.testclient import TestClient
from sqlalchemy import create_engine, select
from sqlalchemy.orm import Session

from app.reasoners.attribution import Attribution, attempt_attribution
from app.store.models import Attempt
from tests.fakes.fake_messages_api import Reply
from tests.fakes.llm_providers import PROVIDERS
from tests.fakes.scripted_reasoner import GARBAGE
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until

BASELINE = {"scenario": "baseline", "mode": "balanced"}
OPENAI = PROVIDERS["openai"]


def run_to_end(client: TestClient, body: dict[str, Any]) -> tuple[str, dict[str, Any]]:
    created = client.post("/runs", json=body)
    assert created.status_code == 202, created.text
    run_id = created.json()["id"]
    assert wait_until(client, run_id)["status"] == "completed"
    return run_id, client.get(f"/runs/{run_id}/trace").json()


def jsonl_decisions(client: TestClient, run_id: str) -> list[dict[str, Any]]:
    text = client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text
    return [line for line in map(json.loads, text.splitlines()) if line["type"] == "decision"]


def who(attempt: dict[str, Any]) -> tuple[str, str | None]:
    return attempt["reasoner"], attempt["why"]


def test_an_llm_run_names_its_model_the_budget_switch_and_the_fallback(
    make_client: ClientFactory,
) -> None:
    with OPENAI.fake() as api:
        # Task 0: garbage at all four tiers (the fallback decides); then good answers
        # until the token budget is spent, then the rules reasoner.
        api.script(*[Reply.answer(GARBAGE)] * 4)
        client = make_client(**OPENAI.settings(api, retries=0))
        run_id, trace = run_to_end(client, {**BASELINE, "reasoner": "openai", "token_budget": 4000})
    decisions = trace["decisions"]
    first = decisions[0]
    assert [who(a) for a in first["attempts"]] == [("openai", None)] * 4
    assert (first["reasoner"], first["why"], first["fallback"]) == ("rules", "fallback", True)
    answered = [d for d in decisions[1:] if d["attempts"][0]["model"] is not None]
    switched = [d for d in decisions[1:] if d["attempts"][0]["model"] is None]
    assert answered and switched  # the budget ran out mid-run
    assert {who(d["attempts"][0]) for d in answered} == {("openai", None)}
    assert {(d["reasoner"], d["why"]) for d in answered} == {("openai", None)}
    assert {who(d["attempts"][0]) for d in switched} == {("rules", "budget_exhausted")}
    assert {(d["reasoner"], d["why"]) for d in switched} == {("rules", "budget_exhausted")}

    exported = jsonl_decisions(client, run_id)
    for line, shown in zip(exported, decisions, strict=True):
        assert (line["reasoner"], line["why"]) == (shown["reasoner"], shown["why"])
        assert [who(a) for a in line["attempt_records"]] == [who(a) for a in shown["attempts"]]
        # Stored in reply_extra, so the hash chain covers it.
        assert [a["reply_extra"]["reasoner"] for a in line["attempt_records"]] == [
            a["reasoner"] for a in shown["attempts"]
        ]

    # A replay's replies are the replay reasoner's, its fallback still the rules reasoner's.
    _, replayed = run_to_end(client, {"reasoner": "replay", "replay_of": run_id})
    assert {who(a) for d in replayed["decisions"] for a in d["attempts"]} == {("replay", None)}
    assert (replayed["decisions"][0]["reasoner"], replayed["decisions"][0]["why"]) == (
        "rules",
        "fallback",
    )


def test_a_rules_run_is_the_rules_reasoner_throughout(client: TestClient) -> None:
    _, trace = run_to_end(client, BASELINE)
    assert {who(a) for d in trace["decisions"] for a in d["attempts"]} == {("rules", None)}
    assert {(d["reasoner"], d["why"]) for d in trace["decisions"]} == {("rules", None)}


def test_attempts_stored_before_attribution_are_derived(
    make_client: ClientFactory,
) -> None:
    with OPENAI.fake() as api:
        client = make_client(**OPENAI.settings(api))
        run_id, _ = run_to_end(client, {**BASELINE, "reasoner": "openai", "token_budget": 4000})
    engine = create_engine(client.app.state.settings.db_url)  # type: ignore[attr-defined]
    with Session(engine) as session, session.begin():
        # What an older version stored: no `reasoner`, the budget switch as `reason`.
        for attempt in session.scalars(select(Attempt).where(Attempt.run_id == run_id)):
            old = {k: v for k, v in (attempt.reply_extra or {}).items() if k != "reasoner"}
            if old.pop("why", None):
                old["reason"] = "budget_exhausted"
            attempt.reply_extra = old
    engine.dispose()
    trace = client.get(f"/runs/{run_id}/trace").json()
    firsts = [d["attempts"][0] for d in trace["decisions"]]
    assert {who(a) for a in firsts if a["model"]} == {("openai", None)}
    assert {who(a) for a in firsts if not a["model"]} == {("rules", "budget_exhausted")}


def test_attribution_of_old_rows() -> None:
    assert attempt_attribution({}, "m", "anthropic") == Attribution("anthropic")
    assert attempt_attribution({}, None, "rules") == Attribution("rules")
    assert attempt_attribution({"replayed_from": "r"}, None, "replay") == Attribution("replay")
    old_budget = {"reasoner": "rules", "reason": "budget_exhausted"}
    assert attempt_attribution(old_budget, None, "anthropic") == Attribution(
        "rules", "budget_exhausted"
    )
    failed = {"error": "HTTP 529", "reasoner": "anthropic"}
    assert attempt_attribution(failed, None, "anthropic") == Attribution("anthropic")
