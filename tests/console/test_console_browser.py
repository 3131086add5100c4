"""The supervisor console in a real headless Chromium against a real server (README.md#console)."""

from __future__ import annotations

import re

import pytest
from axe_playwright_python.sync_playwright import Axe
from playwright.sync_api import BrowserContext, Page, expect

from tests.support.browser import (
    CLIENT_KEY,
    SUPERVISOR_KEY,
    RequestLog,
    sign_in,
    start_run,
    tasks,
    wait_status,
)
from tests.support.server import Server

pytestmark = pytest.mark.e2e


def test_a_supervisor_key_signs_in_and_a_client_key_is_refused(page: Page, server: Server) -> None:
    page.goto(f"{server.url}/console")
    expect(page).to_have_url(re.compile(r"/console/login\?next=/console$"))

    sign_in(page, server, CLIENT_KEY)
    expect(page.get_by_role("heading", name="Client key refused")).to_be_visible()
    expect(page.get_by_text("the console is for supervisors")).to_be_visible()

    sign_in(page, server, "not-a-key-at-all-0000000")
    expect(page.get_by_role("alert")).to_contain_text("not a configured API key")

    sign_in(page, server, SUPERVISOR_KEY)
    expect(page).to_have_url(f"{server.url}/console")
    expect(page.get_by_role("heading", name="Runs")).to_be_visible()
    expect(page.get_by_role("button", name="Sign out")).to_be_visible()

    page.get_by_role("button", name="Sign out").click()
    expect(page).to_have_url(re.compile(r"/console/login$"))
    page.goto(f"{server.url}/console")
    expect(page).to_have_url(re.compile(r"/console/login"))


def test_the_progress_bar_reaches_100_percent_without_reloading(page: Page, server: Server) -> None:
    sign_in(page, server)
    run_id = start_run(server, **tasks(600))
    page.goto(f"{server.url}/console/runs/{run_id}")
    bar = page.locator("progress#progress")
    start = int(bar.get_attribute("value") or 0)
    assert start < 600, "the run finished before the page loaded: nothing live to watch"
    # A marker in the page's JavaScript state survives only if the page is never reloaded.
    page.evaluate("window.__same_page = true")
    expect(bar).to_have_js_property("value", 600, timeout=60_000)
    expect(page.locator("#progress-pct")).to_have_text("100")
    expect(page.locator("#run-status")).to_have_text("completed", timeout=15_000)
    assert page.evaluate("window.__same_page") is True
    expect(page.locator("#events")).to_contain_text("completed")


def test_decision_17_opens_to_its_reasoning_and_eight_scores(page: Page, server: Server) -> None:
    run_id = start_run(server)
    wait_status(server, run_id)
    sign_in(page, server, then=f"/console/runs/{run_id}")
    decision = page.locator("details#decision-17")
    expect(decision).not_to_have_attribute("open", "")
    decision.locator("summary").click()
    expect(decision.locator(".reasoning")).to_be_visible()
    assert len(decision.locator(".reasoning").inner_text().strip()) > 20
    expect(decision.locator(".tradeoff")).to_be_visible()
    scores = decision.locator("table.scores tbody tr")
    expect(scores).to_have_count(8)
    for i in range(8):
        value = scores.nth(i).locator("td").nth(1).inner_text()
        assert re.fullmatch(r"\d\.\d\d", value), value
    # Every attempt, and its prompts and reply on demand.
    decision.get_by_role("link", name=re.compile("Prompts and reply")).first.click()
    expect(decision.locator(".prompts pre").first).to_contain_text("task", ignore_case=True)


def test_a_form_posted_without_its_csrf_token_is_refused(
    page: Page, context: BrowserContext, server: Server
) -> None:
    sign_in(page, server)
    run_id = start_run(server, **tasks(3000))
    forms: list[dict[str, str | float | bool]] = [{}, {"csrf_token": "forged-token"}]
    for form in forms:
        refused = context.request.post(f"{server.url}/console/runs/{run_id}/cancel", form=form)
        assert refused.status == 403
        assert "Form refused" in refused.text()
        refused = context.request.post(f"{server.url}/console/logout", form=form)
        assert refused.status == 403
    # The run was not cancelled and the session still works.
    page.goto(f"{server.url}/console/runs/{run_id}")
    expect(page.locator("#run-status")).not_to_have_text("cancelled")
    # The form as the page renders it (with its token) is accepted.
    page.get_by_role("button", name="Cancel this run").click()
    # The server is the judge of the cancel; then the page (reloaded, so this does not
    # depend on the live stream, which other tests cover) shows it.
    wait_status(server, run_id, "cancelled", timeout=60)
    page.goto(f"{server.url}/console/runs/{run_id}")
    expect(page.locator("#run-status")).to_have_text("cancelled")
    # The sign-in form has its own token too.
    login = context.request.post(
        f"{server.url}/console/login", form={"api_key": SUPERVISOR_KEY}, max_redirects=0
    )
    assert login.status == 403


def test_the_session_cookie_is_httponly_strict_and_opens_no_json_endpoint(
    page: Page, context: BrowserContext, server: Server
) -> None:
    run_id = start_run(server)
    wait_status(server, run_id)
    sign_in(page, server)
    (cookie,) = [c for c in context.cookies() if c["name"] == "ltaa_console"]
    assert cookie["httpOnly"] is True
    assert cookie["sameSite"] == "Strict"
    assert cookie["expires"] > 0  # expiring, not a browser-lifetime cookie
    assert cookie["secure"] is False  # plain http on loopback; Secure over https
    assert page.evaluate("document.cookie") == ""  # no script can read it
    for path in (
        "/runs",
        f"/runs/{run_id}",
        f"/runs/{run_id}/trace",
        f"/runs/{run_id}/trace/verify",
        "/metrics",
    ):
        answer = context.request.get(f"{server.url}{path}")
        assert answer.status == 401, (path, answer.status)
    for path in (f"/runs/{run_id}/cancel", f"/runs/{run_id}/resume"):
        assert context.request.post(f"{server.url}{path}").status == 401
    # The read-only event stream the run page uses is the one exception.
    stream = context.request.get(f"{server.url}/runs/{run_id}/events")
    assert stream.status == 200 and "event: decision" in stream.text()


def test_a_session_of_a_key_removed_from_the_configuration_is_refused(
    context: BrowserContext, tmp_path_factory: pytest.TempPathFactory
) -> None:
    other = "browser-second-supervisor-9Jd3Wk"
    srv = Server(
        tmp_path_factory.mktemp("removed"),
        env={
            "LTAA_API_KEYS": f"{SUPERVISOR_KEY}:supervisor,{other}:supervisor,{CLIENT_KEY}:client"
        },
    )
    srv.start()
    try:
        run_id = start_run(srv)
        page = context.new_page()
        sign_in(page, srv, other)
        page.goto(f"{srv.url}/console/runs/{run_id}")
        expect(page.get_by_role("heading", name=re.compile("^Run "))).to_be_visible()
        srv.stop()
        srv.start(LTAA_API_KEYS=f"{SUPERVISOR_KEY}:supervisor,{CLIENT_KEY}:client")
        page.goto(f"{srv.url}/console/runs/{run_id}")
        expect(page).to_have_url(re.compile(r"/console/login\?next="))
        stream = context.request.get(f"{srv.url}/runs/{run_id}/events")
        assert stream.status == 401
        # The key that is still configured signs in as before.
        sign_in(page, srv, SUPERVISOR_KEY, then=f"/console/runs/{run_id}")
        expect(page.get_by_role("heading", name=re.compile("^Run "))).to_be_visible()
    finally:
        srv.stop()


def test_no_request_leaves_loopback(page: Page, server: Server, requests_seen: RequestLog) -> None:
    run_id = start_run(server)
    wait_status(server, run_id)
    sign_in(page, server)
    page.goto(f"{server.url}/console/runs/{run_id}?decision=3")
    page.locator("details#decision-3").get_by_role("link", name=re.compile("Prompts")).first.click()
    expect(page.locator("details#decision-3 .prompts")).to_be_visible()
    expect(page.locator("#verify-result")).to_be_visible()
    page.goto(f"{server.url}/console/reviews")
    page.goto(f"{server.url}/console/runs/{run_id}/verify")
    assert len(requests_seen.urls) >= 8
    assert requests_seen.outside_loopback() == []
    assert any("/console/static/console.css" in u for u in requests_seen.urls)


SERIOUS = ("serious", "critical")


def _serious_violations(page: Page) -> list[str]:
    results = Axe().run(page)
    return [
        f"{v['id']} ({v['impact']}): {v['help']} — {[n['target'] for n in v['nodes']][:3]}"
        for v in results.response["violations"]
        if v.get("impact") in SERIOUS
    ]


def test_the_four_pages_have_no_serious_or_critical_accessibility_violations(
    page: Page, server: Server
) -> None:
    # The checker is live: it flags what the pages must not have.
    page.set_content("<html><body><input type='text'><img src='data:,'></body></html>")
    assert _serious_violations(page), "axe-core reported nothing on a page with known faults"
    run_id = start_run(server)
    wait_status(server, run_id)
    page.goto(f"{server.url}/console/login")
    found = {"login": _serious_violations(page)}
    sign_in(page, server)
    found["runs"] = _serious_violations(page)
    page.goto(f"{server.url}/console/runs/{run_id}?decision=17")
    expect(page.locator("#verify-result")).to_be_visible()
    found["run"] = _serious_violations(page)
    waiting = start_run(server, review={"task_ids": [5]})
    wait_status(server, waiting, "awaiting_review")
    page.goto(f"{server.url}/console/reviews")
    expect(page.locator("article.review").first).to_be_visible()  # with its forms
    found["reviews"] = _serious_violations(page)
    assert found == {"login": [], "runs": [], "run": [], "reviews": []}


def test_the_runs_list_shows_status_changes_live(page: Page, server: Server) -> None:
    sign_in(page, server)
    run_id = start_run(server, **tasks(400))
    page.goto(f"{server.url}/console?status=")
    row = page.locator(f'tr[data-run="{run_id}"]')
    expect(row).to_be_visible()
    assert row.get_attribute("data-status") in ("queued", "running")
    page.evaluate("window.__same_page = true")
    expect(row.locator(".status")).to_have_text("completed", timeout=60_000)
    assert page.evaluate("window.__same_page") is True
