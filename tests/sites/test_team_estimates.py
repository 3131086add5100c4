"""Learning from team tasks (docs/estimates.md#teams-count-once-per-member) through the API, on
real SQLite: a report on a team task is one report for the task; done or failed counts one outcome
for each member on the feature it covered, and the started -> done pair one observed duration per
member; the rows rebuilt from the record equal the rows written report by report."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from app.sites import rebuild
from tests.api.test_api_bad_requests import assert_error_shape
from tests.plans.test_revisions import revise, wait_status
from tests.plans.test_team_revisions import BODY, ROBOTS, members
from tests.support.site_support import STRENGTH, Tally, estimate_of

SITE = {**BODY, "site": "yard"}


def send(client: TestClient, run_id: str, updates: list[dict[str, Any]]) -> dict[str, Any]:
    answer = client.post(f"/runs/{run_id}/execution", json={"updates": updates})
    assert answer.status_code == 200, answer.text
    return dict(answer.json())


def tally_team(tally: Tally, a: dict[str, Any], done: bool) -> None:
    """By hand: each member on the feature it covered (a single robot on the task's features)."""
    if a.get("team"):
        for m in a["team"]:
            tally.add(m["robot"], [m["feature"]], done)
    else:
        tally.add(a["robot"], a["features"], done)


def test_a_team_task_reported_done_counts_one_success_per_member(
    any_db_client: TestClient,
) -> None:
    client = any_db_client  # SQLite and PostgreSQL: the unique key per member, the rebuild
    created = client.post("/runs", json=SITE)
    assert created.status_code == 202, created.text
    run = wait_status(client, created.json()["id"], "completed")
    run_id = run["id"]
    by_id = {str(a["task_id"]): a for a in run["assignments"]}
    # One report for the team task, not one per member; the task's state is the team's.
    states = send(
        client,
        run_id,
        [
            {"task_id": "beam", "state": "started", "at": "2026-12-01T08:00:00Z"},
            {"task_id": "glaze", "state": "started", "at": "2026-12-01T08:00:00Z"},
        ],
    )
    assert states["states"] == {"beam": "started", "glaze": "started"}
    send(
        client,
        run_id,
        [
            {"task_id": "beam", "state": "done", "at": "2026-12-01T08:30:00Z"},
            {"task_id": "glaze", "state": "failed", "at": "2026-12-01T08:20:00Z"},
            {"task_id": "sweep", "state": "done"},
        ],
    )
    # A member cannot be reported on its own: reports name tasks.
    wrong = client.post(
        f"/runs/{run_id}/execution",
        json={"updates": [{"task_id": members(by_id["beam"])[0], "state": "done"}]},
    )
    assert wrong.status_code == 422, wrong.text
    assert assert_error_shape(wrong.json())[0]["loc"][-1] == "task_id"

    features = {t["id"]: t.get("features") or list(t["team"]) for t in BODY["tasks"]}
    tally = Tally()
    for task_id, done in (("beam", True), ("glaze", False), ("sweep", True)):
        tally_team(tally, {**by_id[task_id], "features": features[task_id]}, done)
    body = client.get("/sites/yard/estimates").json()
    beam = by_id["beam"]["team"]
    assert len(beam) == 2 and all(m["feature"] == "heavy" for m in beam)
    for robot in ROBOTS:
        for feature, prior in robot["success"].items():
            row = estimate_of(body, robot["name"], feature)
            s, f = tally.counts.get((robot["name"], feature), [0, 0])
            assert (row["successes"], row["failures"]) == (s, f), (robot["name"], feature, row)
            assert abs(row["posterior_mean"] - (prior * STRENGTH + s) / (STRENGTH + s + f)) < 1e-9
    for m in beam:  # one success each, on heavy only: the feature it covered
        assert (estimate_of(body, m["robot"], "heavy")["successes"]) == 1
    # One outcome per member: beam 2, glaze 2, sweep 1.
    assert body["reports"] == 5
    observed = {
        r["robot"]: {d["task_type"]: d["observed"] for d in r["durations"]} for r in body["robots"]
    }
    # The started -> done pair teaches each member one observed duration (30 and 20 minutes).
    for m in [*beam, *by_id["glaze"]["team"]]:
        assert observed[m["robot"]].get("Custom", 0) >= 1, observed
    medians = {
        r["robot"]: r["durations"][0]["observed_median_minutes"]
        for r in body["robots"]
        if r["robot"] in {m["robot"] for m in beam} and r["durations"]
    }
    for m in beam:
        if m["robot"] not in {g["robot"] for g in by_id["glaze"]["team"]}:
            assert abs(medians[m["robot"]] - 30.0) < 1e-9

    sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
    comparison = rebuild.compare(sessions=sessions)
    assert comparison.agree and comparison.stored == 5, comparison
    assert rebuild.rebuild(sessions=sessions) == 5
    assert client.get("/sites/yard/estimates").json()["robots"] == body["robots"]
    report = client.get(f"/runs/{run_id}/trace/verify").json()  # the reports' annotations too
    assert report["ok"] is True, report


def test_a_revision_carries_a_team_report_and_it_counts_once(client: TestClient) -> None:
    created = client.post("/runs", json=SITE)
    run = wait_status(client, created.json()["id"], "completed")
    send(
        client,
        run["id"],
        [
            {"task_id": "beam", "state": "started", "at": "2026-12-01T08:00:00Z"},
            {"task_id": "beam", "state": "done", "at": "2026-12-01T08:30:00Z"},
        ],
    )
    revision = revise(client, run["id"], {"changes": [], "reason": "next shift"})["id"]
    state = wait_status(client, revision, "completed")
    beam = next(a for a in state["assignments"] if a["task_id"] == "beam")
    assert beam["pinned"] and beam["execution"]["state"] == "done"
    send(client, revision, [{"task_id": "truss", "state": "failed"}])
    body = client.get("/sites/yard/estimates").json()
    assert body["reports"] == 2 + 3  # the beam's two members once, the truss's three
    sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
    comparison = rebuild.compare(sessions=sessions)
    assert comparison.agree and comparison.stored == 5, comparison


def test_use_learned_and_set_rates_revise_a_team_run(client: TestClient) -> None:
    created = client.post("/runs", json=SITE)
    run = wait_status(client, created.json()["id"], "completed")
    send(client, run["id"], [{"task_id": "truss", "state": "failed"}])
    truss = next(a for a in run["assignments"] if a["task_id"] == "truss")["team"]
    revision = revise(
        client,
        run["id"],
        {
            "changes": [
                {"type": "use_learned"},
                {"type": "set_rates", "robot": "arm", "success": {"careful": 0.5}},
            ],
            "reason": "the truss failed",
        },
    )["id"]
    state = wait_status(client, revision, "completed")
    detail = client.get(f"/runs/{revision}/trace").json()["events"][0]["detail"]
    estimates = client.get("/sites/yard/estimates").json()
    for m in truss:  # each member learned one failure on heavy, the feature it covered
        used = detail["learned"]["robots"][m["robot"]]["heavy"]
        assert (used["successes"], used["failures"], used["basis"]) == (0, 1, "learned")
        assert (
            abs(used["used"] - estimate_of(estimates, m["robot"], "heavy")["posterior_mean"]) < 1e-9
        )
        assert detail["learned"]["robots"][m["robot"]]["careful"]["basis"] == "prior"
    # The revision re-planned with those rates: its decisions' successes are the new teams' means.
    robots = {r["name"]: dict(r["success"]) for r in ROBOTS}
    for name, rates in detail["learned"]["robots"].items():
        robots[name].update({f: r["used"] for f, r in rates.items()})
    robots["arm"]["careful"] = 0.5
    truss_now = next(a for a in state["assignments"] if a["task_id"] == "truss")
    assert not truss_now["pinned"]  # failed: never pinned, re-formed
    expected = sum(robots[m["robot"]][m["feature"]] for m in truss_now["team"]) / 3
    assert abs(truss_now["success"] - expected) < 1e-9
    verify = client.get(f"/runs/{revision}/trace/verify").json()
    assert verify["ok"] is True, verify
