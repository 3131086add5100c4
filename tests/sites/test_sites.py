"""Learning from the site (docs/estimates.md#sites) through the API: sites on runs, estimates that
equal a posterior computed by hand from the reports sent (each counted once across a revision),
learned and sampled runs that record their numbers, and bad input that stores nothing."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from app.sites import rebuild
from tests.plans.test_revisions import BASELINE, completed_run, revise, wait_status
from tests.support.site_support import (
    Tally,
    assert_matches,
    baseline_features,
    baseline_rates,
    estimate_of,
)

S1 = {**BASELINE, "site": "s1"}


def send(client: TestClient, run_id: str, updates: list[dict[str, Any]]) -> None:
    answer = client.post(f"/runs/{run_id}/execution", json={"updates": updates})
    assert answer.status_code == 200, answer.text


def outcomes(client: TestClient, run_id: str, states: dict[str, str]) -> None:
    """Each task started at 08:00 and ended at 08:00 + its index minutes, as `states` say."""
    started = [
        {"task_id": int(t), "state": "started", "at": "2026-12-01T08:00:00Z"} for t in states
    ]
    ended = [
        {"task_id": int(t), "state": s, "at": f"2026-12-01T08:{10 + i:02d}:00+00:00"}
        for i, (t, s) in enumerate(states.items())
    ]
    send(client, run_id, started)
    send(client, run_id, ended)


def assignments(client: TestClient, run_id: str) -> list[dict[str, Any]]:
    return list(client.get(f"/runs/{run_id}").json()["assignments"])


def first_event(client: TestClient, run_id: str) -> dict[str, Any]:
    return dict(client.get(f"/runs/{run_id}/trace").json()["events"][0])


def test_a_run_names_its_site_and_runs_are_filtered_by_it(client: TestClient) -> None:
    plain = completed_run(client)
    on_s1 = completed_run(client, S1)
    assert client.get(f"/runs/{plain}").json()["site"] == "default"
    state = client.get(f"/runs/{on_s1}").json()
    assert (state["site"], state["rates"], state["durations"]) == ("s1", "configured", "configured")
    listed = client.get("/runs", params={"site": "s1"}).json()
    assert [r["id"] for r in listed] == [on_s1] and listed[0]["site"] == "s1"
    assert first_event(client, on_s1)["detail"]["site"] == "s1"
    sites = {s["site"]: s for s in client.get("/sites").json()}
    assert (sites["s1"]["runs"], sites["default"]["runs"]) == (1, 1)


def test_estimates_count_each_report_once_across_a_revision(client: TestClient) -> None:
    features, priors = baseline_features(), baseline_rates()
    first = completed_run(client, S1)
    sent_first = {"0": "done", "1": "failed", "2": "done", "300": "failed", "200": "done"}
    outcomes(client, first, sent_first)
    tally = Tally()
    tally.add_reports(assignments(client, first), sent_first, features)
    # A revision pins the reported tasks and carries their reports: they must not count again.
    revision = revise(client, first, {"changes": [], "reason": "next shift"})["id"]
    wait_status(client, revision, "completed")
    carried = [a for a in assignments(client, revision) if a["execution"]]
    assert {str(a["task_id"]) for a in carried} == {"0", "2", "200"}  # done ones are pinned
    sent_revision = {"3": "done", "4": "failed", "1": "done"}
    outcomes(client, revision, sent_revision)
    tally.add_reports(assignments(client, revision), sent_revision, features)
    assert client.get(f"/runs/{revision}").json()["site"] == "s1"  # inherited

    body = client.get("/sites/s1/estimates").json()
    assert body["reports"] == 8
    assert_matches(body, tally, priors)
    row = estimate_of(body, "heavy", "heavy")
    assert row["interval"][0] <= row["posterior_mean"] <= row["interval"][1]
    durations = [d for r in body["robots"] for d in r["durations"]]
    assert durations and all(d["planned_minutes"] is None for d in durations)
    assert sum(d["observed"] for d in durations) == 8
    assert sum(b["reports"] for b in body["reliability"]) == 8
    # The table written report by report is the one the record implies.
    sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
    comparison = rebuild.compare(sessions=sessions)
    assert comparison.agree and comparison.stored == 8, comparison
    assert rebuild.rebuild(sessions=sessions) == 8
    assert client.get("/sites/s1/estimates").json()["robots"] == body["robots"]


def test_as_of_reads_the_reports_received_by_then(client: TestClient) -> None:
    first = completed_run(client, S1)
    outcomes(client, first, {"0": "done", "2": "failed"})
    at = client.get("/sites/s1/estimates").json()["computed_at"]
    second = completed_run(client, S1)
    outcomes(client, second, {"0": "failed", "5": "failed"})
    before = client.get("/sites/s1/estimates", params={"as_of": at}).json()
    now = client.get("/sites/s1/estimates").json()
    assert (before["reports"], now["reports"]) == (2, 4)
    assert (
        client.get("/sites/s1/estimates", params={"as_of": "2000-01-01T00:00:00Z"}).json()["robots"]
        == []
    )


def test_a_learned_run_plans_with_the_estimates_and_records_them(client: TestClient) -> None:
    features, priors = baseline_features(), baseline_rates()
    first = completed_run(client, S1)
    sent = {str(t): "failed" for t in range(0, 12)}
    outcomes(client, first, sent)
    tally = Tally()
    tally.add_reports(assignments(client, first), sent, features)
    learned = completed_run(client, {**S1, "rates": "learned"})
    event = first_event(client, learned)
    assert event["kind"] == "created" and event["detail"]["rates"] == "learned"
    record = event["detail"]["learned"]
    assert record["source"] == "learned" and record["reports"] == 12
    for robot, rates in priors.items():
        for feature, prior in rates.items():
            rate = record["robots"][robot][feature]
            assert rate["configured"] == prior
            assert abs(rate["used"] - tally.posterior(robot, feature, prior)) < 1e-12
            seen = (robot, feature) in tally.counts
            assert rate["basis"] == ("learned" if seen else "prior")
    fallback = {(f["robot"], f["feature"]) for f in record["fallback"]}
    assert fallback == {(r, f) for r, rs in priors.items() for f in rs} - set(tally.counts)
    # The plan's S values are the learned ones.
    used = {r: {f: v["used"] for f, v in rs.items()} for r, rs in record["robots"].items()}
    for a in assignments(client, learned):
        need = features[str(a["task_id"])]
        assert abs(a["success"] - sum(used[a["robot"]][f] for f in need) / len(need)) < 1e-9
    # The prompt says which rates are learned and on how many reports.
    trace = client.get(f"/runs/{learned}/trace", params={"include": "prompts"}).json()
    prompt = trace["decisions"][0]["attempts"][0]["user_prompt"]
    assert "learned on" in prompt and "reports" in prompt
    # The run's configured rates stay the site's priors.
    body = client.get("/sites/s1/estimates").json()
    assert estimate_of(body, "heavy", "heavy")["prior"] == priors["heavy"]["heavy"]


def test_a_revision_inherits_rates_and_use_learned_picks_robots(client: TestClient) -> None:
    parent = completed_run(client, S1)
    outcomes(client, parent, {str(t): "failed" for t in range(12)})
    revision = revise(
        client,
        parent,
        {"changes": [{"type": "use_learned", "robots": ["heavy"]}], "reason": "heavy fails"},
    )["id"]
    wait_status(client, revision, "completed")
    detail = first_event(client, revision)["detail"]
    bases = {
        robot: {r["basis"] for r in rates.values()}
        for robot, rates in detail["learned"]["robots"].items()
    }
    assert bases["light"] == bases["medium"] == {"configured"}
    assert bases["heavy"] <= {"learned", "prior"} and "learned" in bases["heavy"]
    assert [c["robot"] for c in detail["fleet_changes"]] == ["heavy"]
    # rates: learned on the next revision: every robot; configured again restores them.
    again = revise(client, revision, {"changes": [], "reason": "all", "rates": "learned"})
    learned = again["id"]
    wait_status(client, learned, "completed")
    assert client.get(f"/runs/{learned}").json()["rates"] == "learned"
    back = revise(client, learned, {"changes": [], "reason": "back", "rates": "configured"})
    wait_status(client, back["id"], "completed")
    restored = first_event(client, back["id"])["detail"]
    assert "learned" not in restored
    state = client.get(f"/runs/{back['id']}").json()
    assert state["rates"] == "configured"
    unknown = revise(
        client,
        back["id"],
        {"changes": [{"type": "use_learned", "robots": ["crane"]}], "reason": "x"},
        code=422,
    )
    assert unknown["detail"][0]["loc"] == ["body", "changes", 0, "robots", 0]
    assert "crane" in unknown["detail"][0]["msg"]


def test_a_sampled_run_records_its_draw(client: TestClient) -> None:
    parent = completed_run(client, S1)
    outcomes(client, parent, {str(t): "done" for t in range(10)})
    sampled = completed_run(client, {**S1, "rates": "sampled", "seed": 3})
    record = first_event(client, sampled)["detail"]["learned"]
    drawn = [r for rs in record["robots"].values() for r in rs.values() if r["basis"] == "sampled"]
    assert drawn and all(0.0 <= r["used"] <= 1.0 for r in drawn)


def test_bad_site_input_is_refused_and_nothing_is_stored(client: TestClient) -> None:
    completed_run(client, S1)
    before = len(client.get("/runs").json())
    for body, where in (
        ({**S1, "rates": "guessed"}, "rates"),
        ({**S1, "durations": "sampled"}, "durations"),
        ({**S1, "site": ""}, "site"),
        ({**S1, "site": "a\u0000b"}, "site"),
    ):
        answer = client.post("/runs", json=body)
        assert answer.status_code == 422, answer.text
        assert answer.json()["detail"][0]["loc"][-1] == where
    assert len(client.get("/runs").json()) == before
    missing = client.get("/sites/nowhere/estimates")
    assert missing.status_code == 404 and "GET /sites" in missing.text
    for bad in ("2026-12-01T09:30:00", "yesterday", "1700000000"):
        answer = client.get("/sites/s1/estimates", params={"as_of": bad})
        assert answer.status_code == 422, (bad, answer.text)
        assert answer.json()["detail"][0]["loc"] == ["query", "as_of"]


def test_the_console_site_page_marks_the_rates_far_from_configured(client: TestClient) -> None:
    run_id = completed_run(client, S1)
    robots = {str(a["task_id"]): a["robot"] for a in assignments(client, run_id)}
    heavy_tasks = [t for t, r in robots.items() if r == "heavy"]
    outcomes(client, run_id, dict.fromkeys(heavy_tasks, "failed"))
    runs = client.get("/console")
    assert 'href="/console/sites/s1"' in runs.text
    page = client.get("/console/sites/s1")
    assert page.status_code == 200
    assert 'id="chart-rates"' in page.text and 'id="chart-reliability"' in page.text
    assert 'id="far-from-configured"' in page.text and "heavy · heavy" in page.text
    assert client.get("/console/sites").status_code == 200
    assert client.get("/console/sites/nowhere").status_code == 404


def _durations(client: TestClient, site: str) -> list[dict[str, Any]]:
    body = client.get(f"/sites/{site}/estimates").json()
    return [d for r in body["robots"] for d in r["durations"]]


def test_durations_come_only_from_times_the_site_gave(client: TestClient) -> None:
    # docs/estimates.md, "Durations only from times the site gave".
    run_id = completed_run(client, S1)
    # Started and done in one request without `at`: the outcome counts, no duration.
    send(client, run_id, [{"task_id": 0, "state": "started"}, {"task_id": 0, "state": "done"}])
    # One of the two without `at`, in one request: the server's clock, so no duration either.
    send(
        client,
        run_id,
        [
            {"task_id": 1, "state": "started", "at": "2026-12-01T08:00:00Z"},
            {"task_id": 1, "state": "failed"},
        ],
    )
    # Both with `at`, 20 minutes apart, in one request: 20 minutes.
    send(
        client,
        run_id,
        [
            {"task_id": 2, "state": "started", "at": "2026-12-01T08:00:00Z"},
            {"task_id": 2, "state": "done", "at": "2026-12-01T08:20:00Z"},
        ],
    )
    assert client.get("/sites/s1/estimates").json()["reports"] == 3  # every outcome counts
    durations = _durations(client, "s1")
    assert sum(d["observed"] for d in durations) == 1
    medians = [d["observed_median_minutes"] for d in durations if d["observed"]]
    assert medians == [20.0]
    left_out = [d["left_out"] for d in durations if d["left_out"]]
    assert sum(n for reasons in left_out for n in reasons.values()) == 2
    assert all(set(reasons) == {"together_without_at"} for reasons in left_out)
    # The record says which times were the server's: the rebuilt rows agree.
    sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
    comparison = rebuild.compare(sessions=sessions)
    assert comparison.agree and comparison.stored == 3, comparison
    assert rebuild.rebuild(sessions=sessions) == 3
    assert _durations(client, "s1") == durations
    page = client.get("/console/sites/s1").text
    assert "sent in one request without both times (at)" in page


def test_a_pair_sent_in_two_requests_without_at_teaches_a_duration(client: TestClient) -> None:
    run_id = completed_run(client, S1)
    send(client, run_id, [{"task_id": 0, "state": "started"}])
    send(client, run_id, [{"task_id": 0, "state": "done"}])
    # The two receipts are two readings of the clock: the time between them is observed.
    (row,) = [d for d in _durations(client, "s1") if d["observed"] or d["left_out"]]
    assert (row["observed"], row["left_out"]) == (1, {})
    assert row["observed_median_minutes"] > 0
    sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
    assert rebuild.compare(sessions=sessions).agree


def test_a_pair_given_the_same_time_is_left_out_as_zero_length(client: TestClient) -> None:
    run_id = completed_run(client, S1)
    at = "2026-12-01T08:00:00Z"
    send(
        client,
        run_id,
        [{"task_id": 0, "state": "started", "at": at}, {"task_id": 0, "state": "done", "at": at}],
    )
    (row,) = [d for d in _durations(client, "s1") if d["observed"] or d["left_out"]]
    assert (row["observed"], row["left_out"]) == (0, {"zero_length": 1})
