"""GET /metrics: Prometheus text whose run counts equal what the runs' traces record."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient
from prometheus_client.parser import text_string_to_metric_families
from pydantic import SecretStr

from tests.fakes.fake_messages_api import FakeMessagesAPI, Reply
from tests.fakes.scripted_reasoner import GARBAGE
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until

BASELINE = {"scenario": "baseline", "mode": "balanced"}


def scrape(client: TestClient) -> dict[tuple[str, tuple[tuple[str, str], ...]], float]:
    response = client.get("/metrics")
    assert response.status_code == 200
    assert response.headers["content-type"].startswith("text/plain")
    return {
        (s.name, tuple(sorted(s.labels.items()))): s.value
        for family in text_string_to_metric_families(response.text)
        for s in family.samples
    }


def wait_done(client: TestClient, run_id: str) -> dict[str, Any]:
    return wait_until(client, run_id, timeout=60)  # anything but queued or running


def test_before_any_run_every_series_is_zero(client: TestClient) -> None:
    m = scrape(client)
    assert m[("ltaa_decisions_total", ())] == 0
    assert m[("ltaa_runs", (("status", "completed"),))] == 0
    assert m[("ltaa_retries_total", (("tier", "1"),))] == 0


def test_counts_after_runs_equal_their_traces(make_client: ClientFactory) -> None:
    with FakeMessagesAPI() as api:
        # Task 0: a 429 (retried by the SDK), then two unusable answers: with one retry
        # allowed, the rules fallback decides. Task 1: unusable, then fixed at tier 1.
        api.script(
            Reply.error(429), Reply.answer(GARBAGE), Reply.answer(GARBAGE), Reply.answer(GARBAGE)
        )
        client = make_client(
            anthropic_api_key=SecretStr("test-key"), anthropic_base_url=api.base_url
        )
        baseline = next(s for s in client.get("/scenarios").json() if s["name"] == "baseline")
        six_tasks = {"tasks": baseline["tasks"][:6], "robots": baseline["robots"]}
        llm = client.post(
            "/runs",
            json={**six_tasks, "reasoner": "anthropic", "max_retries": 1, "model": "claude-test"},
        ).json()["id"]
        assert wait_done(client, llm)["status"] == "completed"
        rules = client.post("/runs", json=BASELINE).json()["id"]
        assert wait_done(client, rules)["status"] == "completed"
        tokens_in, tokens_out = api.tokens()
        answered = api.answered()

    trace = client.get(f"/runs/{llm}/trace").json()
    attempts = [a for d in trace["decisions"] for a in d["attempts"]]
    assert [a["tier"] for a in trace["decisions"][0]["attempts"]] == [0, 1]
    assert trace["decisions"][0]["fallback"] is True
    assert [a["accepted"] for a in trace["decisions"][1]["attempts"]] == [False, True]

    m = scrape(client)
    assert m[("ltaa_runs", (("status", "completed"),))] == 2
    assert m[("ltaa_runs", (("status", "running"),))] == 0
    assert m[("ltaa_decisions_total", ())] == 6 + 36
    assert m[("ltaa_fallbacks_total", ())] == 1
    assert m[("ltaa_llm_calls_total", ())] == answered == 6 + 2  # the rules run makes none
    assert m[("ltaa_llm_input_tokens_total", ())] == tokens_in > 0
    assert m[("ltaa_llm_output_tokens_total", ())] == tokens_out > 0
    assert m[("ltaa_llm_transport_retries_total", ())] == 1
    failures = sum(v for (name, _), v in m.items() if name == "ltaa_validation_failures_total")
    assert failures == sum(1 for a in attempts if a["accepted"] is False) == 3
    assert m[("ltaa_retries_total", (("tier", "1"),))] == 2
    assert m[("ltaa_retries_total", (("tier", "2"),))] == 0


def test_request_latency_by_route_template(make_client: ClientFactory) -> None:
    client = make_client()
    run_id = client.post("/runs", json=BASELINE).json()["id"]
    wait_done(client, run_id)
    polls = client.get(f"/runs/{run_id}")
    assert polls.status_code == 200
    client.get("/runs/no-such-run")
    client.get("/no/such/path")

    m = scrape(client)
    count = "ltaa_http_request_duration_seconds_count"
    assert m[(count, (("method", "POST"), ("route", "/runs"), ("status", "202")))] == 1
    assert m[(count, (("method", "GET"), ("route", "/runs/{run_id}"), ("status", "200")))] >= 2
    assert m[(count, (("method", "GET"), ("route", "/runs/{run_id}"), ("status", "404")))] == 1
    assert m[(count, (("method", "GET"), ("route", "unrouted"), ("status", "404")))] == 1
    assert not any(run_id in str(labels) for _, labels in m)

    # Each app has its own registry: a second app has seen none of these requests.
    other = scrape(make_client())
    assert not any(name == count and dict(labels).get("route") == "/runs" for name, labels in other)
