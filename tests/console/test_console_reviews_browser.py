"""Reviews and sign-off from the console (docs/reviews.md, README.md#console): a run whose
review policy names one task pauses there, is resolved from the reviews page and goes on;
a completed run is signed off from its page, which then shows the verified heads."""

from __future__ import annotations

import copy
import re

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.allocation.test_api_teams import TEAM_BODY
from tests.support.browser import CLIENT_KEY, SUPERVISOR_KEY, sign_in, wait_status
from tests.support.server import Server

pytestmark = pytest.mark.e2e


def _run_with_review(server: Server) -> str:
    created = httpx.post(
        f"{server.url}/runs",
        json={
            "scenario": "baseline",
            "reasoner": "rules",
            "review": {"task_ids": [5]},
        },
        headers={"X-API-Key": CLIENT_KEY},
        timeout=30,
    )
    assert created.status_code == 202, created.text
    return str(created.json()["id"])


def _approve_through_the_api(server: Server, run_id: str) -> None:
    httpx.post(
        f"{server.url}/runs/{run_id}/reviews/5",
        json={"action": "approve"},
        headers={"X-API-Key": SUPERVISOR_KEY},
        timeout=30,
    ).raise_for_status()


def test_a_pending_review_is_resolved_from_the_reviews_page_and_the_run_goes_on(
    page: Page, server: Server
) -> None:
    run_id = _run_with_review(server)
    wait_status(server, run_id, "awaiting_review")
    sign_in(page, server, then="/console/reviews")
    review = page.locator("article.review", has=page.locator(f'a[href*="{run_id}"]'))
    expect(review).to_be_visible()
    expect(review.get_by_role("table")).to_contain_text("Regret if chosen")
    review.get_by_role("button", name=re.compile("^Approve")).click()
    page.goto(f"{server.url}/console/runs/{run_id}")
    expect(page.locator("#run-status")).to_have_text("completed", timeout=60_000)
    expect(page.locator("#events")).to_contain_text("review resolved")


def test_a_completed_run_is_signed_off_and_shows_its_verified_heads(
    page: Page, server: Server
) -> None:
    run_id = _run_with_review(server)
    wait_status(server, run_id, "awaiting_review")
    _approve_through_the_api(server, run_id)
    wait_status(server, run_id)
    heads = httpx.get(
        f"{server.url}/runs/{run_id}/trace/verify",
        headers={"X-API-Key": SUPERVISOR_KEY},
        timeout=30,
    ).json()["heads"]
    sign_in(page, server, then=f"/console/runs/{run_id}")
    page.get_by_label("Statement").fill("Checked against the site plan.")
    page.get_by_role("button", name="Sign off").click()
    expect(page.locator("#signoffs")).to_contain_text("Checked against the site plan.")
    expect(page.locator("#head-decisions")).to_have_text(heads["decisions"])
    expect(page.locator("#head-events")).to_have_text(heads["events"])


def test_a_run_page_awaiting_review_follows_a_resolution_made_elsewhere(
    page: Page, server: Server
) -> None:
    """The page of a run waiting for a supervisor streams too: resolved elsewhere (here
    through the API), its status goes on to completed in place, and the page says its
    forms are those of the status it was drawn in."""
    run_id = _run_with_review(server)
    wait_status(server, run_id, "awaiting_review")
    sign_in(page, server, then=f"/console/runs/{run_id}")
    expect(page.locator("#run-status")).to_have_text("awaiting review")
    expect(page.locator("#status-changed")).to_be_hidden()
    page.evaluate("window.__same_page = true")
    _approve_through_the_api(server, run_id)
    expect(page.locator("#run-status")).to_have_text("completed", timeout=60_000)
    expect(page.locator("#status-changed")).to_be_visible()
    expect(page.locator("#status-now")).to_have_text("completed")
    expect(page.locator("#events")).to_contain_text("review resolved")
    assert page.evaluate("window.__same_page") is True
    page.locator("#status-changed").get_by_role("link", name="reload this page").click()
    expect(page.get_by_role("button", name="Sign off")).to_be_visible()


def test_a_team_decision_is_reviewed_with_its_team_and_overridden_with_another(
    page: Page, server: Server
) -> None:
    """docs/reviews.md#reviews-of-team-decisions: the review shows the proposed team and the
    candidate teams; overriding picks one of them, and the decision keeps both."""
    body = {
        **copy.deepcopy(TEAM_BODY),
        "reasoner": "rules",
        "review": {"task_ids": ["beam"]},
    }
    created = httpx.post(
        f"{server.url}/runs", json=body, headers={"X-API-Key": CLIENT_KEY}, timeout=30
    )
    assert created.status_code == 202, created.text
    run_id = str(created.json()["id"])
    wait_status(server, run_id, "awaiting_review")
    pending = httpx.get(
        f"{server.url}/reviews", headers={"X-API-Key": SUPERVISOR_KEY}, timeout=30
    ).json()
    (review,) = [r for r in pending if r["run_id"] == run_id]
    proposed = review["proposal"]["team"]
    sign_in(page, server, then="/console/reviews")
    card = page.locator("article.review", has=page.locator(f'a[href*="{run_id}"]'))
    expect(card.locator(".proposed-team")).to_have_text(
        " + ".join(f"{m['robot']} ({m['feature']})" for m in proposed)
    )
    table = card.get_by_role("table")
    expect(table).to_contain_text("Candidate teams")
    expect(table.locator("tbody tr")).to_have_count(len(review["alternatives"]))
    choice = card.get_by_label("Give the task to the team")
    options = choice.locator("option")
    expect(options).to_have_count(len(review["alternatives"]) - 1)  # all but the proposal
    label = options.first.inner_text()
    choice.select_option(index=0)
    card.get_by_label("Reason (recorded with the decision)").fill("the crane is booked")
    card.get_by_role("button", name="Override").click()
    expect(page.locator("#run-status")).to_have_text("completed", timeout=60_000)
    decision = httpx.get(
        f"{server.url}/runs/{run_id}/trace", headers={"X-API-Key": SUPERVISOR_KEY}, timeout=30
    ).json()["decisions"][0]
    chosen = [m["robot"] for m in decision["team"]]
    assert label.startswith(" + ".join(chosen)), (label, chosen)
    assert decision["review"]["overridden_from_team"] == proposed
    assert decision["review"]["reason"] == "the crane is booked"
