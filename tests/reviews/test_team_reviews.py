"""Supervisor reviews of team decisions (docs/reviews.md#reviews-of-team-decisions), in process:
the pending review lists the proposed team and the rules reasoner's candidate teams (success,
cap-feasibility and exact regret if chosen), `approve` keeps the proposal, `override` takes a
whole team (checked as a team; one robot on a team task is a 422 saying to send `team`), the
decision records `overridden_from` and `overridden_from_team`, loads follow the reviewer's team,
and the trace, its chains and a replay hold."""

from __future__ import annotations

import copy
import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.allocation.test_api_teams import TEAM_BODY
from tests.audit.test_docs_check_trace import check_trace_source
from tests.reviews.test_reviews import EVERY, WAITING, _approve_all, _awaiting, _pending
from tests.support.clients import ClientFactory
from tests.support.offline_check import check_offline
from tests.support.polling import wait_until

ROBOTS = ("crane", "arm", "lifter")


def team_run(client: TestClient, **changes: Any) -> str:
    body = {**copy.deepcopy(TEAM_BODY), "mode": "balanced", "review": EVERY, **changes}
    r = client.post("/runs", json=body)
    assert r.status_code == 202, r.text
    return str(r.json()["id"])


def key(team: list[dict[str, str]]) -> frozenset[tuple[str, str]]:
    return frozenset((m["robot"], m["feature"]) for m in team)


def test_the_review_of_a_team_decision_lists_the_team_and_candidate_teams_with_exact_regret(
    client: TestClient,
) -> None:
    run_id = team_run(client)
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    assert (review["task_index"], review["task_id"]) == (0, "beam")
    proposal = review["proposal"]
    assert [m["feature"] for m in proposal["team"]] == ["heavy", "heavy"]
    assert proposal["robot"] == proposal["team"][0]["robot"]
    assert review["units"] == [
        {"feature": "heavy", "count": 2, "robots": ["crane", "arm", "lifter"]}
    ]
    alts = {key(a["team"]): a for a in review["alternatives"]}
    # Every pair of distinct robots covers the beam's two heavy units: three candidate teams,
    # the best by success first, the proposal among them.
    assert len(alts) == 3 and key(proposal["team"]) in alts
    successes = [a["success"] for a in review["alternatives"]]
    assert successes == sorted(successes, reverse=True)
    rate = {"crane": 0.9, "arm": 0.3, "lifter": 0.8}
    for a in review["alternatives"]:
        members = [m["robot"] for m in a["team"]]
        assert a["robot"] == members[0] and a["load"] == 0
        assert a["success"] == pytest.approx(sum(rate[m] for m in members) / 2)
    # Regret if chosen, in success points over the queue, against the exact optimum given that
    # team: POST /allocate with the team pinned (docs/living-plans.md#pins-in-allocate).
    plan = {**copy.deepcopy(TEAM_BODY), "mode": "balanced", "solver": "optimal"}
    best = client.post("/allocate", json=plan).json()["metrics"]["expected_success"]
    for a in review["alternatives"]:
        assert a["cap_feasible"] is True
        pinned = client.post(
            "/allocate", json={**plan, "pinned": [{"task_id": "beam", "team": a["team"]}]}
        )
        es = pinned.json()["metrics"]["expected_success"]
        assert a["regret_if_chosen"] == pytest.approx((best - es) * 4 * 100, abs=1e-6)


def test_approving_every_team_decision_gives_the_plan_without_review(client: TestClient) -> None:
    plain = client.post("/runs", json={**copy.deepcopy(TEAM_BODY), "mode": "balanced"}).json()
    plain_state = wait_until(client, plain["id"])
    run_id = team_run(client)
    reviews = _approve_all(client, run_id)
    assert [r["task_index"] for r in reviews] == [0, 1, 2, 3]
    assert "team" in reviews[1]["proposal"] and "team" not in reviews[2]["proposal"]
    done = client.get(f"/runs/{run_id}").json()
    assert [a.get("team") for a in done["assignments"]] == [
        a.get("team") for a in plain_state["assignments"]
    ]
    trace = client.get(f"/runs/{run_id}/trace").json()
    assert all(d["review"]["action"] == "approve" for d in trace["decisions"])
    assert client.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True


def test_an_override_with_a_team_is_stored_and_the_rest_follows(
    client: TestClient, tmp_path: Path
) -> None:
    run_id = team_run(client)
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    proposed = review["proposal"]["team"]
    other = next(a["team"] for a in review["alternatives"] if key(a["team"]) != key(proposed))
    answer = client.post(
        f"/runs/{run_id}/reviews/0",
        json={"action": "override", "team": other[::-1], "reason": "the lifter is on the slab"},
    )
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert key(body["team"]) == key(other) and body["robot"] == body["team"][0]["robot"]
    _awaiting(client, run_id)
    second = _pending(client, run_id)
    members = {m["robot"] for m in other}
    loads = client.get(f"/runs/{run_id}/trace").json()["decisions"][0]["loads_after"]
    assert loads == [1 if name in members else 0 for name in ROBOTS]  # the reviewer's team
    assert second["task_index"] == 1
    _approve_all(client, run_id)

    trace = client.get(f"/runs/{run_id}/trace").json()
    first = trace["decisions"][0]
    assert first["team"] == body["team"] and first["robot"] == body["team"][0]["robot"]
    assert first["review"]["overridden_from"] == proposed[0]["robot"]
    assert first["review"]["overridden_from_team"] == proposed
    assert first["review"]["reason"] == "the lifter is on the slab"
    rate = {"crane": 0.9, "arm": 0.3, "lifter": 0.8}
    assert first["expected_success"] == pytest.approx(sum(rate[m] for m in members) / 2)
    run = client.get(f"/runs/{run_id}").json()
    assert run["assignments"][0]["team"] == body["team"]
    assert run["assignments"][0]["review"]["overridden_from_team"] == proposed
    workload = {name: 0 for name in ROBOTS}
    for a in run["assignments"]:
        for m in a.get("team") or [{"robot": a["robot"]}]:
            workload[m["robot"]] += 1
    assert run["metrics"]["workload"] == workload
    verify = client.get(f"/runs/{run_id}/trace/verify").json()
    assert verify["ok"] is True, verify
    # Offline too; the proposed team is in the chain: editing it breaks the decision's link.
    export = tmp_path / "run.jsonl"
    export.write_text(client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text)
    script = tmp_path / "check_trace.py"
    script.write_text(check_trace_source())
    assert check_offline(export, script=script).returncode == 0
    lines = export.read_text().splitlines()
    at = next(
        i
        for i, x in enumerate(lines)
        if (json.loads(x).get("review") or {}).get("overridden_from_team")
    )
    edited = json.loads(lines[at])
    edited["review"]["overridden_from_team"][0]["robot"] = "nobody"
    lines[at] = json.dumps(edited)
    export.write_text("\n".join(lines) + "\n")
    broken = check_offline(export, script=script)
    assert broken.returncode == 1 and "decision" in broken.stdout + broken.stderr

    # A replay re-applies the reviewer's team without waiting.
    replay = client.post("/runs", json={"reasoner": "replay", "replay_of": run_id}).json()["id"]
    state = wait_until(client, replay, WAITING)
    assert state["status"] == "completed", state
    replayed = client.get(f"/runs/{replay}/trace").json()["decisions"]
    assert [d.get("team") for d in replayed] == [d.get("team") for d in trace["decisions"]]
    assert [d["review"] for d in replayed] == [d["review"] for d in trace["decisions"]]


BAD: list[tuple[str, dict[str, Any], list[Any], str]] = [
    (
        "one_robot_on_a_team_task",
        {"action": "override", "robot": "arm", "reason": "r"},
        ["robot"],
        "send `team`",
    ),
    (
        "approve_with_a_team",
        {"action": "approve", "team": [{"robot": "arm", "feature": "heavy"}]},
        ["team"],
        "approval",
    ),
    (
        "unknown_robot",
        {
            "action": "override",
            "reason": "r",
            "team": [{"robot": "arm", "feature": "heavy"}, {"robot": "zep", "feature": "heavy"}],
        },
        ["team", 1, "robot"],
        "unknown robot 'zep'",
    ),
    (
        "a_robot_twice",
        {
            "action": "override",
            "reason": "r",
            "team": [{"robot": "arm", "feature": "heavy"}, {"robot": "arm", "feature": "heavy"}],
        },
        ["team", 1, "robot"],
        "distinct",
    ),
    (
        "a_feature_the_task_lacks",
        {"action": "override", "reason": "r", "team": [{"robot": "arm", "feature": "careful"}]},
        ["team", 0, "feature"],
        "no unit of 'careful'",
    ),
    (
        "a_unit_left_uncovered",
        {"action": "override", "reason": "r", "team": [{"robot": "arm", "feature": "heavy"}]},
        ["team"],
        "needs 2 robot(s) for 'heavy'",
    ),
    (
        "robot_not_the_first_member",
        {
            "action": "override",
            "reason": "r",
            "robot": "lifter",
            "team": [{"robot": "arm", "feature": "heavy"}, {"robot": "lifter", "feature": "heavy"}],
        },
        ["robot"],
        "first unit",
    ),
    (
        "no_reason",
        {
            "action": "override",
            "team": [{"robot": "arm", "feature": "heavy"}, {"robot": "lifter", "feature": "heavy"}],
        },
        ["reason"],
        "reason",
    ),
]


def test_bad_team_overrides_are_a_422_naming_the_field_and_leave_the_review_pending(
    client: TestClient,
) -> None:
    run_id = team_run(client)
    _awaiting(client, run_id)
    for name, body, loc, words in BAD:
        r = client.post(f"/runs/{run_id}/reviews/0", json=body)
        assert r.status_code == 422, (name, r.text)
        detail = r.json()["detail"]
        assert any(d["loc"] == ["body", *loc] and words in d["msg"] for d in detail), (name, detail)
    assert _pending(client, run_id)["task_index"] == 0  # nothing half-written
    # The same run's one-robot decision (the sweep) refuses a team.
    for _ in range(2):
        assert (
            client.post(
                f"/runs/{run_id}/reviews/{_pending(client, run_id)['task_index']}",
                json={"action": "approve"},
            ).status_code
            == 200
        )
        _awaiting(client, run_id)
    assert _pending(client, run_id)["task_index"] == 2
    r = client.post(
        f"/runs/{run_id}/reviews/2",
        json={
            "action": "override",
            "reason": "r",
            "team": [{"robot": "arm", "feature": "careful"}],
        },
    )
    assert r.status_code == 422 and r.json()["detail"][0]["loc"] == ["body", "team"], r.text


def test_a_team_the_cap_forbids_is_a_422_saying_why(client: TestClient) -> None:
    """W = 1 with no slack: once the carry is on the crane, a beam team holding it breaks the
    cap (a team not among the candidates: checked against the run's own problem)."""
    body = {
        "tasks": [
            {"id": "carry", "name": "Carry", "features": ["heavy"]},
            {"id": "beam", "name": "Lift beam", "team": {"heavy": 2}},
        ],
        "robots": [
            {"name": "crane", "success": {"heavy": 0.9}},
            {"name": "lifter", "success": {"heavy": 0.8}},
            {"name": "arm", "success": {"heavy": 0.3}},
        ],
        "max_deviation": 0,
        "review": {"task_ids": ["beam"]},
    }
    run_id = client.post("/runs", json=body).json()["id"]
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    carried = client.get(f"/runs/{run_id}/trace").json()["decisions"][0]["robot"]
    assert all(carried not in {m["robot"] for m in a["team"]} for a in review["alternatives"])
    partner = next(name for name in ("crane", "lifter", "arm") if name != carried)
    team = [{"robot": carried, "feature": "heavy"}, {"robot": partner, "feature": "heavy"}]
    r = client.post(
        f"/runs/{run_id}/reviews/1", json={"action": "override", "reason": "r", "team": team}
    )
    assert r.status_code == 422, r.text
    (item,) = r.json()["detail"]
    assert item["loc"] == ["body", "team"] and "above the cap" in item["msg"], item
    ok = client.post(
        f"/runs/{run_id}/reviews/1",
        json={"action": "override", "reason": "r", "team": review["alternatives"][-1]["team"]},
    )
    assert ok.status_code == 200, ok.text
    assert wait_until(client, run_id, WAITING)["status"] == "completed"


def test_a_robots_trigger_fires_for_any_member(client: TestClient) -> None:
    run_id = team_run(client, review={"robots": ["arm"]})
    state = wait_until(client, run_id, WAITING)
    reviews = []
    while state["status"] == "awaiting_review":
        review = _pending(client, run_id)
        reviews.append(review)
        members = {m["robot"] for m in review["proposal"].get("team") or [review["proposal"]]}
        assert "arm" in members and review["triggers"] == ["robots"]
        client.post(f"/runs/{run_id}/reviews/{review['task_index']}", json={"action": "approve"})
        state = wait_until(client, run_id, WAITING)
    assert state["status"] == "completed"
    done = client.get(f"/runs/{run_id}").json()["assignments"]
    with_arm = [
        a["task_index"]
        for a in done
        if "arm" in {m["robot"] for m in a.get("team") or [{"robot": a["robot"]}]}
    ]
    assert [r["task_index"] for r in reviews] == with_arm and with_arm


def test_the_cli_shows_teams_and_reads_a_team_override(client: TestClient) -> None:
    """`ltaa reviews` names a team decision's members; `ltaa review --team` reads
    robot:feature per unit (the feature after the last colon)."""
    from rich.console import Console

    from app.cli.reviews import parse_team, print_reviews

    run_id = team_run(client)
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    out = Console(record=True, width=400)
    print_reviews([review], out)
    text = out.export_text()
    assert " + ".join(m["robot"] for m in review["proposal"]["team"]) in text
    assert parse_team("crane:heavy, lift:er:heavy") == [
        {"robot": "crane", "feature": "heavy"},
        {"robot": "lift:er", "feature": "heavy"},
    ]
    with pytest.raises(Exception, match="robot:feature"):
        parse_team("crane")


def test_a_restart_keeps_a_team_review_waiting_and_a_new_process_applies_the_team(
    make_client: ClientFactory, settings: Any
) -> None:
    """The interrupt's payload (the team and its candidates) survives the process; the
    resolution is applied by the new one (the graph re-runs finalize from its top)."""
    first = make_client()
    run_id = team_run(first)
    _awaiting(first, run_id)
    review = _pending(first, run_id)
    first.__exit__(None, None, None)
    again = make_client(data_dir=settings.data_dir)  # the same store, auto-resume on
    assert again.get(f"/runs/{run_id}").json()["status"] == "awaiting_review"
    assert _pending(again, run_id) == review
    other = next(
        a["team"]
        for a in review["alternatives"]
        if key(a["team"]) != key(review["proposal"]["team"])
    )
    answer = again.post(
        f"/runs/{run_id}/reviews/0", json={"action": "override", "team": other, "reason": "r"}
    )
    assert answer.status_code == 200, answer.text
    _approve_all(again, run_id)
    first_decision = again.get(f"/runs/{run_id}/trace").json()["decisions"][0]
    assert key(first_decision["team"]) == key(other)
    assert again.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True


def test_a_timed_team_decision_is_reviewed_and_the_reviewers_team_is_placed_in_time(
    client: TestClient,
) -> None:
    """In time (docs/schedules.md#teams-in-a-run-in-time) the candidates' cap-feasibility also
    holds "members free in time"; the reviewer's team is the one placed, in both its members'
    lanes, from the last member's arrival."""
    from tests.allocation.test_api_timed_teams import TIMED_TEAM_BODY

    body = {**copy.deepcopy(TIMED_TEAM_BODY), "reasoner": "rules", "review": {"task_ids": ["beam"]}}
    run_id = client.post("/runs", json=body).json()["id"]
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    proposed = review["proposal"]["team"]
    other = next(
        a["team"]
        for a in review["alternatives"]
        if a["cap_feasible"] and key(a["team"]) != key(proposed)
    )
    answer = client.post(
        f"/runs/{run_id}/reviews/{review['task_index']}",
        json={"action": "override", "team": other, "reason": "the lifter is on the slab"},
    )
    assert answer.status_code == 200, answer.text
    assert wait_until(client, run_id, WAITING)["status"] == "completed"
    run = client.get(f"/runs/{run_id}").json()
    beam = next(a for a in run["assignments"] if a["task_id"] == "beam")
    assert key(beam["team"]) == key(other)
    assert beam["review"]["overridden_from_team"] == proposed
    schedule = client.get(f"/runs/{run_id}/schedule").json()
    for m in other:  # the reviewer's team in every member's lane, over the same minutes
        lane = schedule["robots"][m["robot"]]["lane"]
        worked = [i for i in lane if i["kind"] == "task" and i["task_id"] == "beam"]
        assert [(i["start"], i["end"]) for i in worked] == [(beam["start"], beam["end"])]
    assert client.get(f"/runs/{run_id}/trace/verify").json()["ok"] is True


def test_a_large_fleet_lists_the_best_teams_and_takes_an_unlisted_one_checked_by_the_run(
    client: TestClient,
) -> None:
    """Six robots make 15 two-robot teams: the review lists the best twelve (the proposal among
    them); a team it does not list is checked against the run's own problem and taken."""
    rates = {f"r{i}": round(0.95 - 0.1 * i, 2) for i in range(6)}
    body = {
        "tasks": [
            {"id": "beam", "name": "Lift beam", "team": {"heavy": 2}},
            *({"id": f"c{i}", "name": f"Carry {i}", "features": ["heavy"]} for i in range(4)),
        ],
        "robots": [{"name": n, "success": {"heavy": s}} for n, s in rates.items()],
        "mode": "success_focused",
        "review": {"task_ids": ["beam"]},
    }
    run_id = client.post("/runs", json=body).json()["id"]
    _awaiting(client, run_id)
    review = _pending(client, run_id)
    listed = [key(a["team"]) for a in review["alternatives"]]
    assert len(listed) == 12 and key(review["proposal"]["team"]) in listed
    worst = [{"robot": "r5", "feature": "heavy"}, {"robot": "r4", "feature": "heavy"}]
    assert key(worst) not in listed
    answer = client.post(
        f"/runs/{run_id}/reviews/0",
        json={"action": "override", "team": worst, "reason": "the others are booked"},
    )
    assert answer.status_code == 200, answer.text
    assert answer.json()["team"] == worst  # the members of one feature in the order sent
    assert wait_until(client, run_id, WAITING)["status"] == "completed"
    beam = client.get(f"/runs/{run_id}").json()["assignments"][0]
    assert beam["team"] == worst and beam["success"] == pytest.approx((0.45 + 0.55) / 2)
