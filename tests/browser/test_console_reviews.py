"""Reviews and sign-off from the console (SPEC 11 through SPEC 13's pages).

Written against SPEC section 11's API (POST /runs with `review`, GET /reviews,
POST /runs/{id}/reviews/{task_index}, POST /runs/{id}/signoff), which is issue 12's and
not in this build yet: both tests are expected to fail until it is (they fail at once, on
the run request that names a review policy).
"""

from __future__ import annotations

import re

import httpx
import pytest
from playwright.sync_api import Page, expect

from tests.browser.conftest import CLIENT_KEY, SUPERVISOR_KEY, sign_in, wait_status
from tests.e2e.server import Server

pytestmark = [
    pytest.mark.e2e,
    pytest.mark.xfail(
        reason="needs issue 12's review and sign-off API (POST /runs `review`, GET /reviews, "
        "POST /runs/{id}/reviews/{task_index}, POST /runs/{id}/signoff), not on main yet",
        strict=False,
    ),
]


def _run_with_review(server: Server) -> str:
    created = httpx.post(
        f"{server.url}/runs",
        json={
            "scenario": "baseline",
            "reasoner": "rules",
            "review": {"on": ["every_decision"], "task_ids": [5]},
        },
        headers={"X-API-Key": CLIENT_KEY},
        timeout=30,
    )
    assert created.status_code == 202, created.text
    return str(created.json()["id"])


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
    httpx.post(
        f"{server.url}/runs/{run_id}/reviews/5",
        json={"action": "approve"},
        headers={"X-API-Key": SUPERVISOR_KEY},
        timeout=30,
    ).raise_for_status()
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
