"""Team overrides checked as the run decides them (docs/reviews.md#reviews-of-team-decisions): on a
timed run a team the review did not list is checked in time too, from the decisions made so far
(a guided run's in its plan's order), and the console's team field refuses anything but a list
of members with a 422 page."""

from __future__ import annotations

from fastapi.testclient import TestClient

from tests.console.test_console import TOKEN
from tests.reviews.test_reviews import WAITING, _awaiting, _pending
from tests.reviews.test_team_reviews import team_run
from tests.support.polling import wait_until
from tests.support.timed_checks import feasibility_errors


def test_an_unlisted_timed_team_not_free_in_time_is_a_422_saying_why(client: TestClient) -> None:
    """In time the review lists only teams whose members are free in time; a team it does not
    list is checked against the run's problem in time too: two members whose shifts end before
    the beam could (minute 20 against 30) are refused, not placed outside their shifts."""
    rates = {f"r{i}": round(0.95 - 0.1 * i, 2) for i in range(6)}
    short = {"r4", "r5"}
    body = {
        "tasks": [
            {"id": "beam", "name": "Lift beam", "team": {"heavy": 2}, "duration": 30},
            *(
                {"id": f"c{i}", "name": f"Carry {i}", "features": ["heavy"], "duration": 10}
                for i in range(4)
            ),
        ],
        "robots": [
            {"name": n, "success": {"heavy": s}, **({"available": [0, 20]} if n in short else {})}
            for n, s in rates.items()
        ],
        "mode": "success_focused",
        "reasoner": "rules",
        "review": {"task_ids": ["beam"]},
        "start": "2026-12-07T07:00:00+01:00",
    }
    run_id = client.post("/runs", json=body).json()["id"]
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    assert all(not short & {m["robot"] for m in a["team"]} for a in review["alternatives"])
    late = [{"robot": "r5", "feature": "heavy"}, {"robot": "r4", "feature": "heavy"}]
    r = client.post(
        f"/runs/{run_id}/reviews/0", json={"action": "override", "reason": "r", "team": late}
    )
    assert r.status_code == 422, r.text
    (item,) = r.json()["detail"]
    assert item["loc"] == ["body", "team"] and "shift" in item["msg"], item
    assert _pending(client, run_id)["task_index"] == 0  # nothing half-written
    ok = [{"robot": "r3", "feature": "heavy"}, {"robot": "r2", "feature": "heavy"}]
    answer = client.post(
        f"/runs/{run_id}/reviews/0", json={"action": "override", "reason": "r", "team": ok}
    )
    assert answer.status_code == 200, answer.text
    assert wait_until(client, run_id, WAITING)["status"] == "completed"
    schedule = client.get(f"/runs/{run_id}/schedule").json()
    assert feasibility_errors(body, schedule) == []


def test_a_guided_timed_team_run_checks_an_unlisted_team_in_its_plans_order(
    client: TestClient,
) -> None:
    """A guided timed run decides in its stored plan's order (here the second beam before the
    first): the override's check in time replays the decisions in that order too, so a team
    with a member whose shift ends (minute 35) before the beam could is refused there as well."""
    rates = {f"r{i}": round(0.95 - 0.1 * i, 2) for i in range(6)}
    carries = [
        {"id": f"c{i}", "name": f"Carry {i}", "features": ["heavy"], "duration": 10}
        for i in range(4)
    ]
    carries[0]["duration"], carries[3]["after"] = 40, ["c0"]
    body = {
        "tasks": [
            *carries,
            {"id": "beam", "name": "Beam", "team": {"heavy": 2}, "duration": 30, "after": ["c1"]},
            {"id": "beam2", "name": "Beam 2", "team": {"heavy": 2}, "duration": 20},
        ],
        "robots": [
            {"name": n, "success": {"heavy": s}, **({"available": [0, 35]} if i >= 4 else {})}
            for i, (n, s) in enumerate(rates.items())
        ],
        "mode": "balanced",
        "reasoner": "rules",
        "guidance": "optimizer",
        "review": {"task_ids": ["beam"]},
        "start": "2026-12-07T07:00:00+01:00",
    }
    run_id = client.post("/runs", json=body).json()["id"]
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    assert review["task_index"] == 4
    decided = [d["task_index"] for d in client.get(f"/runs/{run_id}/trace").json()["decisions"]]
    assert 5 in decided  # the plan's order, not the unguided one
    late = [{"robot": "r5", "feature": "heavy"}, {"robot": "r2", "feature": "heavy"}]
    r = client.post(
        f"/runs/{run_id}/reviews/4", json={"action": "override", "reason": "r", "team": late}
    )
    assert r.status_code == 422, r.text
    (item,) = r.json()["detail"]
    assert item["loc"] == ["body", "team"] and "shift" in item["msg"], item


def test_a_malformed_team_in_the_console_form_is_a_422_page_and_the_review_stays_pending(
    client: TestClient,
) -> None:
    """The console's team field is JSON from its select; anything else sent to it (deeply
    nested, not a list of members) is refused with a page naming the field, never a 500."""
    run_id = team_run(client)
    _awaiting(client, run_id)
    token = TOKEN.search(client.get("/console/reviews").text)
    assert token
    for value in ("[" * 5000, "{}", '"crane"', "[[1, 2]]", '[{"robot": "crane"}]', "7"):
        answer = client.post(
            f"/console/runs/{run_id}/reviews/0",
            data={"csrf_token": token[1], "action": "override", "team": value, "reason": "r"},
            follow_redirects=False,
        )
        assert answer.status_code == 422, (value[:20], answer.status_code, answer.text[:300])
        assert "team" in answer.text
    assert _pending(client, run_id)["task_index"] == 0
