"""llm_scope over HTTP: POST /runs and /allocate (ltaa) ask the model only for contested
decisions, store the scope in the run's spec, and a replay copies it."""

from __future__ import annotations

import json
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.fakes.llm_providers import PROVIDERS
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until

BASELINE = {"scenario": "baseline", "mode": "balanced"}
OPENAI = PROVIDERS["openai"]


def run_to_end(client: TestClient, body: dict[str, Any]) -> tuple[dict[str, Any], dict[str, Any]]:
    created = client.post("/runs", json=body)
    assert created.status_code == 202, created.text
    state = wait_until(client, created.json()["id"])
    assert state["status"] == "completed", state
    return state, client.get(f"/runs/{state['id']}/trace").json()


def test_a_contested_run_asks_the_model_only_for_contested_decisions(
    make_client: ClientFactory,
) -> None:
    with OPENAI.fake() as api:
        client = make_client(**OPENAI.settings(api))
        state, trace = run_to_end(
            client, {**BASELINE, "reasoner": "openai", "llm_scope": "contested"}
        )
        asked = len(api.requests)
        everything, _ = run_to_end(client, {**BASELINE, "reasoner": "openai"})
    firsts = [d["attempts"][0] for d in trace["decisions"]]
    by_model = [a for a in firsts if a["model"] is not None]
    clear = [a for a in firsts if a["model"] is None]
    assert len(by_model) == asked == state["usage"]["llm_calls"] and 0 < asked <= 0.4 * 36
    assert {(a["reasoner"], a["why"]) for a in by_model} == {("openai", None)}
    assert {(a["reasoner"], a["why"]) for a in clear} == {("rules", "clear-cut")}
    assert {(d["reasoner"], d["why"]) for d in trace["decisions"] if d["attempts"][0] in clear} == {
        ("rules", "clear-cut")
    }
    # The fake answers as the rules would: the same plan for a fraction of the calls.
    assert state["assignments"] == everything["assignments"]
    assert everything["usage"]["llm_calls"] == 36

    header = json.loads(
        client.get(f"/runs/{state['id']}/trace", params={"format": "jsonl"}).text.splitlines()[0]
    )
    assert (header["request"]["llm_scope"], header["request"]["llm_margin"]) == ("contested", 5.0)

    # A replay copies the scope (and replays every recorded reply, clear-cut ones too).
    replay, again = run_to_end(client, {"reasoner": "replay", "replay_of": state["id"]})
    assert replay["assignments"] == state["assignments"]
    assert {a["reasoner"] for d in again["decisions"] for a in d["attempts"]} == {"replay"}
    conflict = client.post(
        "/runs", json={"reasoner": "replay", "replay_of": state["id"], "llm_scope": "all"}
    )
    assert conflict.status_code == 422
    assert conflict.json()["detail"][0]["loc"] == ["body", "llm_scope"]


def test_contested_with_guidance_keeps_regret_zero(make_client: ClientFactory) -> None:
    with OPENAI.fake() as api:  # the fake follows the optimizer's guidance when given
        client = make_client(**OPENAI.settings(api))
        state, _ = run_to_end(
            client,
            {
                **BASELINE,
                "reasoner": "openai",
                "llm_scope": "contested",
                "llm_margin": 3,
                "guidance": "optimizer",
            },
        )
    assert state["regret"] == pytest.approx(0.0, abs=1e-9)
    assert 0 < state["usage"]["llm_calls"] < 36


@pytest.mark.parametrize(
    ("body", "loc"),
    [
        ({"llm_scope": "some"}, ["body", "llm_scope"]),
        ({"llm_margin": -1}, ["body", "llm_margin"]),
        ({"llm_margin": "5"}, ["body", "llm_margin"]),
    ],
)
def test_a_bad_scope_is_a_422_naming_the_field(
    client: TestClient, body: dict[str, Any], loc: list[str]
) -> None:
    response = client.post("/runs", json={**BASELINE, **body})
    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == loc


def test_allocate_with_a_contested_scope(make_client: ClientFactory) -> None:
    with OPENAI.fake() as api:
        client = make_client(**OPENAI.settings(api))
        answers = {}
        for scope in ("all", "contested"):
            response = client.post(
                "/allocate",
                json={
                    **BASELINE,
                    "solver": "ltaa",
                    "options": {"reasoner": "openai", "llm_scope": scope},
                },
            )
            assert response.status_code == 200, response.text
            answers[scope] = response.json()
        calls = len(api.requests)
    assert answers["all"]["usage"]["llm_calls"] == 36
    contested = answers["contested"]["usage"]["llm_calls"]
    assert 0 < contested <= 0.4 * 36 and calls == 36 + contested
    assert answers["all"]["assignments"] == answers["contested"]["assignments"]
    bad = client.post(
        "/allocate",
        json={**BASELINE, "solver": "ltaa", "options": {"llm_scope": "most"}},
    )
    assert bad.status_code == 422
