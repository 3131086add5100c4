"""POST /schedules/import?site=: the draft's robots take the site's learned rates (the
posterior means GET /sites/{site}/estimates answers, computed by hand here), an unknown
site is a 404 on the query, and the filled draft of plain links starts a run as it is
(docs/exchange.md#rates-from-a-site). No Java: the file is our own writer's."""

from __future__ import annotations

from fastapi.testclient import TestClient

from app.exchange import read_mspdi
from tests.plans.test_revisions import completed_run, wait_status
from tests.sites.test_sites import S1, assignments, outcomes
from tests.support.exchange_files import small_mspdi
from tests.support.site_support import Tally, baseline_features, baseline_rates


def test_site_rates_fill_the_drafts_robots_and_the_draft_runs(client: TestClient) -> None:
    run = completed_run(client, S1)
    sent = {"0": "done", "1": "failed", "2": "done", "3": "done"}
    outcomes(client, run, sent)
    tally = Tally()
    tally.add_reports(assignments(client, run), sent, baseline_features())
    answer = client.post("/schedules/import", params={"site": "s1"}, content=small_mspdi())
    assert answer.status_code == 200, answer.text
    body = answer.json()
    priors = baseline_rates()
    needed = {"heavy", "careful", "dexterous"}
    for robot in body["robots"]:
        expected = {
            f: round(tally.posterior(robot["name"], f, priors[robot["name"]][f]), 4) for f in needed
        }
        assert robot["success"] == expected, robot
    rates = body["source"]["rates"]
    assert (rates["site"], rates["filled"], rates["not_on_site"]) == ("s1", ["heavy", "light"], [])
    # Everything else is the plain import's.
    plain = read_mspdi(small_mspdi()).to_dict()
    assert (body["tasks"], body["skipped"]) == (plain["tasks"], plain["skipped"])

    draft = read_mspdi(small_mspdi())
    draft.robots[:] = body["robots"]
    started = client.post("/runs", json={**draft.request(), "site": "s1"})
    assert started.status_code == 202, started.text
    state = wait_status(client, started.json()["id"], "completed")
    assert len(state["assignments"]) == 3


def test_an_unknown_site_is_a_404_and_a_bad_one_a_422(client: TestClient) -> None:
    missing = client.post("/schedules/import", params={"site": "nowhere"}, content=small_mspdi())
    assert missing.status_code == 404, missing.text
    (detail,) = missing.json()["detail"]
    assert detail["loc"] == ["query", "site"] and "GET /sites" in detail["msg"]
    empty = client.post("/schedules/import", params={"site": ""}, content=small_mspdi())
    assert empty.status_code == 422
    assert empty.json()["detail"][0]["loc"] == ["query", "site"]
