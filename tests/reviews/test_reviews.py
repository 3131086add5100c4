"""Supervisor reviews of decisions (docs/reviews.md#which-decisions-wait-for-review), in process:
the policy, the pause before a decision is stored, GET /reviews, resolutions (approve, override,
conflicts, bad input), cancel, replay and metrics. The end-to-end tests
(tests/reviews/test_reviews_e2e.py) kill the real server around the same steps."""

from __future__ import annotations

import threading
from typing import Any

import pytest
from fastapi.testclient import TestClient
from pydantic import SecretStr

from app.http.auth import key_fingerprint
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until
from tests.support.sse import parse_events

WAITING = ("awaiting_review", "completed", "failed", "cancelled")
EVERY = {"on": ["every_decision"]}
# Three tasks, three robots and no slack (max_deviation 0): each robot takes exactly one
# task, so once a robot has one, the cap forbids it for the rest.
TIGHT: dict[str, Any] = {
    "tasks": [
        {"id": "T0", "name": "Lift", "features": ["heavy"]},
        {"id": "T1", "name": "Place", "features": ["heavy"]},
        {"id": "T2", "name": "Weld", "features": ["careful"]},
    ],
    "robots": [
        {"name": "a", "success": {"heavy": 0.9, "careful": 0.5}},
        {"name": "b", "success": {"heavy": 0.6, "careful": 0.8}},
        {"name": "c", "success": {"heavy": 0.5, "careful": 0.6}},
    ],
    "max_deviation": 0,
}


def _awaiting(client: TestClient, run_id: str) -> dict[str, Any]:
    state = wait_until(client, run_id, WAITING)
    assert state["status"] == "awaiting_review", state
    return state


def _pending(client: TestClient, run_id: str) -> dict[str, Any]:
    mine = [r for r in client.get("/reviews").json() if r["run_id"] == run_id]
    assert len(mine) == 1, mine
    return dict(mine[0])


def _events(client: TestClient, run_id: str) -> list[str]:
    return [e["kind"] for e in client.get(f"/runs/{run_id}/trace").json()["events"]]


def _approve_all(client: TestClient, run_id: str) -> list[dict[str, Any]]:
    seen: list[dict[str, Any]] = []
    while True:
        state = wait_until(client, run_id, WAITING)
        if state["status"] != "awaiting_review":
            assert state["status"] == "completed", state
            return seen
        review = _pending(client, run_id)
        seen.append(review)
        answer = client.post(
            f"/runs/{run_id}/reviews/{review['task_index']}", json={"action": "approve"}
        )
        assert answer.status_code == 200, answer.text


def test_every_decision_pauses_36_times_and_approvals_give_the_proposals_plan(
    client: TestClient,
) -> None:
    plain = wait_until(client, client.post("/runs", json={"scenario": "baseline"}).json()["id"])
    run_id = client.post("/runs", json={"scenario": "baseline", "review": EVERY}).json()["id"]
    reviews = _approve_all(client, run_id)
    assert [r["task_index"] for r in reviews] == list(range(36))
    done = client.get(f"/runs/{run_id}").json()
    proposals = [r["proposal"]["robot"] for r in reviews]
    assert [a["robot"] for a in done["assignments"]] == proposals
    assert proposals == [a["robot"] for a in plain["assignments"]]  # same as without review
    # Task ids as the request gave them (the baseline's are numbers), as the run shows them.
    assert [r["task_id"] for r in reviews] == [a["task_id"] for a in done["assignments"]]
    assert all(isinstance(r["task_id"], int) for r in reviews)
    assert done["resumes"] == 0  # resolutions are not crash resumes
    kinds = _events(client, run_id)
    assert kinds.count("review_requested") == kinds.count("review_resolved") == 36
    assert "resumed" not in kinds and kinds[-1] == "completed"
    trace = client.get(f"/runs/{run_id}/trace").json()
    assert all(d["review"]["action"] == "approve" for d in trace["decisions"])
    assert all(d["review"]["triggers"] == ["every_decision"] for d in trace["decisions"])
    assert client.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True


def test_the_review_shows_the_proposal_and_every_alternative_with_exact_regret(
    client: TestClient,
) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    assert (review["task_index"], review["task_id"], review["task_name"]) == (0, "T0", "Lift")
    assert review["triggers"] == ["every_decision"]
    assert set(review["proposal"]) == {
        "robot",
        "success",
        "reasoning",
        "tradeoff",
        "quality",
        "confidence",
        "fallback",
    }
    alts = {a["robot"]: a for a in review["alternatives"]}
    assert list(alts) == ["a", "b", "c"]
    assert all(a["load"] == 0 and a["cap_feasible"] for a in alts.values())
    # Each robot takes one task. T0 to a: best a,c,b = 0.9 + 0.5 + 0.8 = 2.2 (the optimum);
    # to c: c,a,b = 2.2; to b: b,a,c = 0.6 + 0.9 + 0.6 = 2.1. So choosing b gives away 0.1
    # of summed success: 10 points over the rest of the queue, not 10 / 3 per task.
    regrets = {name: a["regret_if_chosen"] for name, a in alts.items()}
    assert regrets == pytest.approx({"a": 0.0, "b": 10.0, "c": 0.0}, abs=1e-6)
    assert review["requested_at"].endswith("Z")


def test_override_stores_the_reviewers_robot_and_the_rest_follows(
    make_client: ClientFactory,
) -> None:
    supervisor = "supervisor-key-Jm3Kd8Qw2Vx6Bn5Y"
    client = make_client(
        api_keys=SecretStr(f"{supervisor}:supervisor"),
        api_key_names=f"{key_fingerprint(supervisor)}=Dana",
    )
    client.headers["Authorization"] = f"Bearer {supervisor}"
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    proposed = _pending(client, run_id)["proposal"]["robot"]
    other = next(r for r in ("a", "b", "c") if r != proposed)
    answer = client.post(
        f"/runs/{run_id}/reviews/0",
        json={"action": "override", "robot": other, "reason": "a is booked for the crane"},
    )
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert body["reviewer"] == "Dana" and body["robot"] == other and body["status"] == "queued"

    _awaiting(client, run_id)
    second = _pending(client, run_id)
    assert second["task_index"] == 1
    loads = {a["robot"]: a["load"] for a in second["alternatives"]}
    assert loads[other] == 1 and sum(loads.values()) == 1  # the override drives the loads
    infeasible = {a["robot"]: a["cap_feasible"] for a in second["alternatives"]}
    assert infeasible[other] is False
    assert _approve_all(client, run_id)  # the rest approved

    trace = client.get(f"/runs/{run_id}/trace").json()
    first = trace["decisions"][0]
    assert first["robot"] == other
    assert first["review"] == {
        "action": "override",
        "reviewer": "Dana",
        "reason": "a is booked for the crane",
        "at": body["at"],
        "triggers": ["every_decision"],
        "overridden_from": proposed,
    }
    assert first["loads_after"][["a", "b", "c"].index(other)] == 1
    robots = [d["robot"] for d in trace["decisions"]]
    assert sorted(robots) == ["a", "b", "c"]  # the cap held with the reviewer's robot
    s = {"a": 0.9, "b": 0.6, "c": 0.5}
    assert first["expected_success"] == s[other]
    assert client.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True


def test_bad_resolutions_are_4xx_naming_the_problem(client: TestClient) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    url = f"/runs/{run_id}/reviews/0"

    def error(body: dict[str, Any], status: int) -> dict[str, Any]:
        response = client.post(url, json=body)
        assert response.status_code == status, response.text
        return dict(response.json()["detail"][0])

    missing_reason = error({"action": "override", "robot": "b"}, 422)
    assert missing_reason["loc"] == ["body", "reason"]
    assert error({"action": "override", "robot": "b", "reason": "  "}, 422)["loc"] == [
        "body",
        "reason",
    ]
    unknown = error({"action": "override", "robot": "zeppelin", "reason": "x"}, 422)
    assert unknown["loc"] == ["body", "robot"] and "zeppelin" in unknown["msg"]
    assert error({"action": "approve", "robot": "b"}, 422)["loc"] == ["body", "robot"]
    assert error({"action": "maybe"}, 422)["loc"] == ["body", "action"]
    # Another task than the pending one, and an unknown run.
    other = client.post(f"/runs/{run_id}/reviews/2", json={"action": "approve"})
    assert other.status_code == 409 and other.json()["detail"][0]["loc"] == ["path", "task_index"]
    assert client.post(f"/runs/{'0' * 32}/reviews/0", json={"action": "approve"}).status_code == 404

    assert client.post(url, json={"action": "approve"}).status_code == 200
    again = client.post(url, json={"action": "approve"})
    assert again.status_code == 409 and "resolved" in again.json()["detail"][0]["msg"]

    _awaiting(client, run_id)
    taken = next(a["robot"] for a in _pending(client, run_id)["alternatives"] if a["load"] == 1)
    infeasible = client.post(
        f"/runs/{run_id}/reviews/1",
        json={"action": "override", "robot": taken, "reason": "x"},
    )
    assert infeasible.status_code == 422
    detail = infeasible.json()["detail"][0]
    assert detail["loc"] == ["body", "robot"] and taken in detail["msg"]
    assert detail["type"] == "cap_infeasible"


def test_of_two_concurrent_resolutions_exactly_one_wins(client: TestClient) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    barrier = threading.Barrier(2)
    codes: list[int] = []

    def resolve(body: dict[str, Any]) -> None:
        barrier.wait()
        codes.append(client.post(f"/runs/{run_id}/reviews/0", json=body).status_code)

    threads = [
        threading.Thread(target=resolve, args=({"action": "approve"},)),
        threading.Thread(
            target=resolve, args=({"action": "override", "robot": "c", "reason": "x"},)
        ),
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    assert sorted(codes) == [200, 409]
    _awaiting(client, run_id)
    assert _events(client, run_id).count("review_resolved") == 1


def test_cancelling_a_run_awaiting_review_closes_the_review(client: TestClient) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    cancelled = client.post(f"/runs/{run_id}/cancel")
    assert cancelled.status_code == 200 and cancelled.json()["status"] == "cancelled"
    assert [r for r in client.get("/reviews").json() if r["run_id"] == run_id] == []
    late = client.post(f"/runs/{run_id}/reviews/0", json={"action": "approve"})
    assert late.status_code == 409 and "closed" in late.json()["detail"][0]["msg"]
    assert _events(client, run_id)[-2:] == ["review_closed", "cancelled"]
    assert client.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True


def test_resume_of_a_run_awaiting_review_is_409(client: TestClient) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    response = client.post(f"/runs/{run_id}/resume")
    assert response.status_code == 409 and "review" in response.json()["detail"][0]["msg"]


def test_a_restart_leaves_the_run_waiting(make_client: ClientFactory, settings: Any) -> None:
    first = make_client()
    run_id = first.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(first, run_id)
    before = _events(first, run_id)
    first.__exit__(None, None, None)
    again = make_client(data_dir=settings.data_dir)  # the same store, auto-resume on
    assert again.get(f"/runs/{run_id}").json()["status"] == "awaiting_review"
    assert _events(again, run_id) == before  # nothing re-ran, nothing was re-requested
    assert again.post(f"/runs/{run_id}/reviews/0", json={"action": "approve"}).status_code == 200
    assert _approve_all(again, run_id)
    assert _events(again, run_id).count("review_requested") == 3


def test_a_replay_reproduces_the_overrides_without_waiting(client: TestClient) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    proposed = _pending(client, run_id)["proposal"]["robot"]
    other = next(r for r in ("a", "b", "c") if r != proposed)
    client.post(
        f"/runs/{run_id}/reviews/0", json={"action": "override", "robot": other, "reason": "r"}
    )
    _approve_all(client, run_id)
    original = client.get(f"/runs/{run_id}/trace").json()["decisions"]

    replay = client.post("/runs", json={"reasoner": "replay", "replay_of": run_id}).json()["id"]
    state = wait_until(client, replay, WAITING)
    assert state["status"] == "completed", state  # never waited
    replayed = client.get(f"/runs/{replay}/trace").json()
    assert [d["robot"] for d in replayed["decisions"]] == [d["robot"] for d in original]
    assert [d["review"] for d in replayed["decisions"]] == [d["review"] for d in original]
    assert "review_requested" not in [e["kind"] for e in replayed["events"]]


@pytest.mark.parametrize(
    ("review", "loc"),
    [
        ({"robots": ["zeppelin"]}, ["body", "review", "robots", 0]),
        ({"features": ["flying"]}, ["body", "review", "features", 0]),
        ({"task_ids": ["T0", "nope"]}, ["body", "review", "task_ids", 1]),
        ({"on": ["sometimes"]}, ["body", "review", "on", 0]),
        ({"quality_below": 2}, ["body", "review", "quality_below"]),
        ({"regret_above": -1}, ["body", "review", "regret_above"]),
        ({"whenever": True}, ["body", "review", "whenever"]),
    ],
)
def test_a_bad_review_policy_is_a_422_naming_the_field(
    client: TestClient, review: dict[str, Any], loc: list[Any]
) -> None:
    response = client.post("/runs", json={**TIGHT, "review": review})
    assert response.status_code == 422, response.text
    assert response.json()["detail"][0]["loc"] == loc


def test_triggers_by_task_feature_and_robot_only_fire_where_they_hold(client: TestClient) -> None:
    policy = {"task_ids": ["T2"], "features": [], "robots": []}
    run_id = client.post("/runs", json={**TIGHT, "review": policy}).json()["id"]
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    assert (review["task_index"], review["triggers"]) == (2, ["task_ids"])
    client.post(f"/runs/{run_id}/reviews/2", json={"action": "approve"})
    assert wait_until(client, run_id, WAITING)["status"] == "completed"


def test_metrics_show_pending_reviews_and_time_to_resolution(client: TestClient) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    assert "ltaa_reviews_pending 1.0" in client.get("/metrics").text
    client.post(f"/runs/{run_id}/reviews/0", json={"action": "approve"})
    text = client.get("/metrics").text
    assert "ltaa_review_resolution_seconds_count 1.0" in text


def test_a_client_key_may_not_list_or_resolve_reviews(make_client: ClientFactory) -> None:
    key = "client-key-7Hq2vN9xLp4Rt8Zw"
    client = make_client(api_keys=SecretStr(f"{key}:client"))
    headers = {"Authorization": f"Bearer {key}"}
    assert client.get("/reviews", headers=headers).status_code == 403
    response = client.post(
        f"/runs/{'0' * 32}/reviews/0", json={"action": "approve"}, headers=headers
    )
    assert response.status_code == 403


def test_review_requests_and_resolutions_stream_as_review_events(
    make_client: ClientFactory,
) -> None:
    client = make_client(events_max_stream_s=0.5)
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    client.post(f"/runs/{run_id}/reviews/0", json={"action": "approve"})
    _awaiting(client, run_id)
    with client.stream("GET", f"/runs/{run_id}/events") as response:
        events = list(parse_events(response.iter_lines()))
    reviews = [
        (e.data["kind"], e.data["detail"]["task_index"]) for e in events if e.event == "review"
    ]
    assert reviews == [("review_requested", 0), ("review_resolved", 0), ("review_requested", 1)]
    decisions = [e.data for e in events if e.event == "decision"]
    assert len(decisions) == 1 and decisions[0]["review"]["action"] == "approve"
    assert "review_requested" not in [e.data["kind"] for e in events if e.event == "run"]


def test_a_resolution_retried_with_its_idempotency_key_gets_the_same_answer(
    client: TestClient,
) -> None:
    run_id = client.post("/runs", json={**TIGHT, "review": EVERY}).json()["id"]
    _awaiting(client, run_id)
    url, key = f"/runs/{run_id}/reviews/0", {"Idempotency-Key": "review-0"}
    first = client.post(url, json={"action": "approve"}, headers=key)
    again = client.post(url, json={"action": "approve"}, headers=key)
    assert first.status_code == again.status_code == 200
    assert again.json() == first.json() and again.headers["Idempotent-Replayed"] == "true"
    other = client.post(url, json={"action": "override", "robot": "c", "reason": "x"}, headers=key)
    assert (
        other.status_code == 409 and other.json()["detail"][0]["type"] == "idempotency_key_reused"
    )
    assert client.post(url, json={"action": "approve"}).status_code == 409  # no key: a conflict
    _awaiting(client, run_id)
    assert _events(client, run_id).count("review_resolved") == 1


RACES = 40
TERMINAL = ("completed", "cancelled", "failed")


def _race_cancel_and_approve(client: TestClient, run_id: str) -> dict[str, int | str]:
    """Cancel and approve the run's pending review at the same moment, from two threads."""
    barrier = threading.Barrier(2)
    answers: dict[str, int | str] = {}

    def call(name: str, path: str, body: dict[str, Any] | None) -> None:
        barrier.wait()
        try:
            answers[name] = client.post(path, json=body).status_code
        except Exception as exc:  # the TestClient re-raises the cause of a 500
            answers[name] = f"{type(exc).__name__}: {exc}"

    threads = [
        threading.Thread(target=call, args=("cancel", f"/runs/{run_id}/cancel", None)),
        threading.Thread(
            target=call, args=("approve", f"/runs/{run_id}/reviews/0", {"action": "approve"})
        ),
    ]
    for t in threads:
        t.start()
    for t in threads:
        t.join()
    return answers


def test_cancel_racing_an_approval_answers_2xx_or_409_and_leaves_one_consistent_state(
    client: TestClient,
) -> None:
    outcomes: list[tuple[str, int | str, int | str]] = []
    for _ in range(RACES):
        run_id = client.post("/runs", json={**TIGHT, "review": {"task_ids": ["T0"]}}).json()["id"]
        _awaiting(client, run_id)
        answers = _race_cancel_and_approve(client, run_id)
        cancel, approve = answers["cancel"], answers["approve"]
        assert cancel in (200, 409) and approve in (200, 409), answers
        state = wait_until(client, run_id, TERMINAL)
        events = _events(client, run_id)
        # The review ended one way only: resolved by the approval or closed by the cancel.
        assert (events.count("review_resolved"), events.count("review_closed")) == (
            (1, 0) if approve == 200 else (0, 1)
        ), (answers, events)
        if approve == 409:
            assert cancel == 200 and state["status"] == "cancelled", (answers, state)
            assert state["assignments"] == [], state
        if cancel == 409:  # only once the run had ended, so the approval came first
            assert approve == 200 and state["status"] == "completed", (answers, state)
        # One terminal event, the last, matching the status; nothing after it.
        assert sum(events.count(kind) for kind in TERMINAL) == 1, (answers, events)
        assert events[-1] == state["status"] != "failed", (answers, events, state)
        assert [r for r in client.get("/reviews").json() if r["run_id"] == run_id] == []
        assert client.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True
        outcomes.append((state["status"], cancel, approve))
    # Both orders happened, or the race was not a race.
    assert {approve for _, _, approve in outcomes} == {200, 409}, outcomes
