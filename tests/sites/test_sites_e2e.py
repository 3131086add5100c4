"""Learning from the site (docs/estimates.md#the-model) on a real server: the estimates equal a
posterior computed by hand from the reports sent, each counted once across a revision; `as_of` reads
the past; sites are separate; a learned run records its numbers and replays identically
after 100 more reports; bad input is refused and stores nothing."""

from __future__ import annotations

from collections.abc import Iterator
from typing import Any

import httpx
import pytest

from tests.support.server import Server
from tests.support.site_support import Tally, assert_matches, baseline_features, baseline_rates

pytestmark = pytest.mark.e2e

BASELINE = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
TASK_IDS = [str(t) for t in baseline_features()]


def finished(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return bool(state["status"] == "completed")


def run(server: Server, c: httpx.Client, **body: Any) -> dict[str, Any]:
    created = c.post("/runs", json={**BASELINE, **body})
    assert created.status_code == 202, created.text
    return server.wait_for(created.json()["id"], finished)


def steps(outcomes: dict[str, str]) -> list[list[dict[str, Any]]]:
    """The two reports that say the tasks happened: each `started`, then each outcome."""
    return [
        [{"task_id": int(t), "state": "started", "at": "2026-12-01T08:00:00Z"} for t in outcomes],
        [
            {"task_id": int(t), "state": s, "at": "2026-12-01T09:30:00+01:00"}
            for t, s in outcomes.items()
        ],
    ]


def report(c: httpx.Client, run_id: str, outcomes: dict[str, str]) -> None:
    for updates in steps(outcomes):
        answer = c.post(f"/runs/{run_id}/execution", json={"updates": updates})
        assert answer.status_code == 200, answer.text


def estimates(c: httpx.Client, site: str, **params: str) -> dict[str, Any]:
    answer = c.get(f"/sites/{site}/estimates", params=params)
    assert answer.status_code == 200, answer.text
    body: dict[str, Any] = answer.json()
    return body


@pytest.fixture(scope="module")
def server(tmp_path_factory: pytest.TempPathFactory) -> Iterator[Server]:
    srv = Server(tmp_path_factory.mktemp("sites"))
    srv.start()
    yield srv
    srv.stop()


def test_estimates_are_the_posterior_of_the_reports_sent_each_counted_once(
    server: Server,
) -> None:
    features, priors = baseline_features(), baseline_rates()
    with server.client() as c:
        first = run(server, c, site="s1")
        second = run(server, c, site="s1")
        sent_first = {"0": "done", "1": "failed", "2": "done", "200": "failed", "300": "done"}
        report(c, first["id"], sent_first)
        tally = Tally()
        tally.add_reports(first["assignments"], sent_first, features)
        # Revised after reports: the revision carries the reports of the tasks it pins.
        created = c.post(
            f"/runs/{first['id']}/revisions", json={"changes": [], "reason": "next shift"}
        )
        assert created.status_code == 202, created.text
        revision = server.wait_for(created.json()["id"], finished)
        assert revision["site"] == "s1"
        assert sum(1 for a in revision["assignments"] if a["execution"]) == 3
        sent_revision = {"3": "done", "4": "failed", "201": "done"}
        report(c, revision["id"], sent_revision)
        tally.add_reports(revision["assignments"], sent_revision, features)
        before_second = estimates(c, "s1")["computed_at"]
        first_alone = Tally(counts={k: list(v) for k, v in tally.counts.items()})
        sent_second = {"5": "failed", "6": "failed", "7": "done", "8": "done"}
        report(c, second["id"], sent_second)
        tally.add_reports(second["assignments"], sent_second, features)
        other = run(server, c, site="s2")
        report(c, other["id"], {t: "failed" for t in TASK_IDS[:20]})

        now = estimates(c, "s1")
        assert now["reports"] == 12
        assert_matches(now, tally, priors)
        past = estimates(c, "s1", as_of=before_second)
        assert past["reports"] == 8
        assert_matches(past, first_alone, priors)
        # Sites are separate: s2's twenty failures never reach s1, nor s1's outcomes s2.
        s2 = estimates(c, "s2")
        assert s2["reports"] == 20
        assert sum(f["successes"] for r in s2["robots"] for f in r["features"]) == 0
        listed = {s["site"]: s for s in c.get("/sites").json()}
        assert (listed["s1"]["runs"], listed["s1"]["reports"]) == (3, 12)
        assert c.get("/runs", params={"site": "s2"}).json()[0]["id"] == other["id"]


def test_a_learned_run_replays_identically_after_more_reports(server: Server) -> None:
    with server.client() as c:
        seed = run(server, c, site="s3")
        report(c, seed["id"], {t: "failed" if i % 3 else "done" for i, t in enumerate(TASK_IDS)})
        learned = run(server, c, site="s3", rates="learned")
        first = c.get(f"/runs/{learned['id']}/trace").json()["events"][0]
        record = first["detail"]["learned"]
        now = estimates(c, "s3")
        for robot in now["robots"]:
            for f in robot["features"]:
                used = record["robots"][robot["robot"]][f["feature"]]["used"]
                assert abs(used - f["posterior_mean"]) < 1e-12  # its priors are the site's
        # 108 more reports move the estimates...
        for _ in range(3):
            more = run(server, c, site="s3")
            report(c, more["id"], dict.fromkeys(TASK_IDS, "done"))
        moved = estimates(c, "s3")
        assert moved["reports"] == 36 + 108
        assert moved["robots"] != now["robots"]
        # ... and neither the replay nor the verification of the learned run moves with them.
        created = c.post("/runs", json={"reasoner": "replay", "replay_of": learned["id"]})
        assert created.status_code == 202, created.text
        replay = server.wait_for(created.json()["id"], finished)
        pairs = [(a["robot"], a["success"]) for a in replay["assignments"]]
        assert pairs == [(a["robot"], a["success"]) for a in learned["assignments"]]
        verify = c.get(f"/runs/{learned['id']}/trace/verify").json()
        assert verify["ok"] is True, verify
        again = c.get(f"/runs/{learned['id']}/trace").json()["events"][0]
        assert again["detail"]["learned"] == record


def test_bad_input_is_refused_and_stores_nothing(server: Server) -> None:
    with server.client() as c:
        runs_before = len(c.get("/runs", params={"limit": 500}).json())
        bad_rates = c.post("/runs", json={**BASELINE, "site": "s1", "rates": "guessed"})
        assert bad_rates.status_code == 422
        assert bad_rates.json()["detail"][0]["loc"] == ["body", "rates"]
        assert c.get("/sites/nowhere/estimates").status_code == 404
        bad_time = c.get("/sites/s1/estimates", params={"as_of": "2026-12-01T09:30:00"})
        assert bad_time.status_code == 422
        assert bad_time.json()["detail"][0]["loc"] == ["query", "as_of"]
        assert len(c.get("/runs", params={"limit": 500}).json()) == runs_before
        assert "nowhere" not in {s["site"] for s in c.get("/sites").json()}


def test_the_cli_shows_a_sites_estimates_from_a_real_server(server: Server) -> None:
    from typer.testing import CliRunner

    from app.cli import cli

    with server.client() as c:
        done = run(server, c, site="cli-site")
        report(c, done["id"], {"0": "failed", "1": "done"})
        together = [{"task_id": 2, "state": "started"}, {"task_id": 2, "state": "done"}]
        sent = c.post(f"/runs/{done['id']}/execution", json={"updates": together})
        assert sent.status_code == 200, sent.text
    runner = CliRunner()
    env = {"COLUMNS": "240"}
    listed = runner.invoke(cli, ["estimates", "--url", server.url], env=env)
    assert listed.exit_code == 0, listed.output
    assert "cli-site" in listed.output
    shown = runner.invoke(cli, ["estimates", "cli-site", "--url", server.url], env=env)
    assert shown.exit_code == 0, shown.output
    assert "Site cli-site: 3 report(s)" in shown.output and "dexterous" in shown.output
    # Task 2's pair came in one request without `at`: its outcome counts, its times do not.
    assert "1 sent together without at" in shown.output, shown.output
    missing = runner.invoke(cli, ["estimates", "elsewhere", "--url", server.url], env=env)
    assert missing.exit_code == 1 and "404" in missing.output
    bad = runner.invoke(
        cli, ["estimates", "cli-site", "--as-of", "yesterday", "--url", server.url], env=env
    )
    assert bad.exit_code == 1 and "422" in bad.output
