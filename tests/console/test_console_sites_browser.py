"""The console's site page (docs/estimates.md#the-site-page) in a real browser: reached from the
runs list and a run's page, each robot's learned rates with intervals and report counts as the API
states them, the rates far from the configured ones marked, the reliability plot; axe-clean."""

from __future__ import annotations

from typing import Any

import pytest
from playwright.sync_api import Page, expect

from tests.console.test_console_browser import _serious_violations
from tests.support.browser import CLIENT_KEY, sign_in, start_run, wait_status
from tests.support.server import Server

pytestmark = pytest.mark.e2e

HEADERS = {"X-API-Key": CLIENT_KEY}


def _json(server: Server, path: str) -> Any:
    with server.client() as c:
        answer = c.get(path, headers=HEADERS)
    assert answer.status_code == 200, answer.text
    return answer.json()


def _report(server: Server, run_id: str, outcomes: dict[Any, str]) -> None:
    """Each task started and ended in one request, without `at`: outcomes, no durations."""
    updates = [
        {"task_id": t, "state": state} for t, s in outcomes.items() for state in ("started", s)
    ]
    with server.client() as c:
        answer = c.post(f"/runs/{run_id}/execution", json={"updates": updates}, headers=HEADERS)
    assert answer.status_code == 200, answer.text


def test_the_site_page_shows_the_estimates_the_api_states(page: Page, server: Server) -> None:
    run_id = start_run(server, site="yard-7")
    wait_status(server, run_id)
    assignments = _json(server, f"/runs/{run_id}")["assignments"]
    # The heavy robot fails every task it was given; the others succeed.
    _report(
        server,
        run_id,
        {a["task_id"]: "failed" if a["robot"] == "heavy" else "done" for a in assignments},
    )
    api = _json(server, "/sites/yard-7/estimates")

    sign_in(page, server)
    link = page.locator(f'tr[data-run="{run_id}"] td.site a')
    expect(link).to_have_text("yard-7")
    link.click()
    expect(page).to_have_url(f"{server.url}/console/sites/yard-7")
    expect(page.get_by_role("heading", name="Site yard-7", exact=True)).to_be_visible()
    for robot in api["robots"]:
        table = page.locator(f'table.estimates[data-robot="{robot["robot"]}"]')
        for f in robot["features"]:
            row = table.locator(f'tr[data-feature="{f["feature"]}"]')
            cells = row.locator("td")
            expect(cells.nth(1)).to_have_text(str(f["successes"]))
            expect(cells.nth(2)).to_have_text(str(f["failures"]))
            expect(cells.nth(3)).to_contain_text(f"{100 * f['posterior_mean']:.1f}%")
            low, high = f["interval"]
            expect(cells.nth(4)).to_have_text(f"{100 * low:.1f}% – {100 * high:.1f}%")
            if f["marked"]:
                expect(row).to_have_class("marked")
        # Durations only from times the site gave (docs/estimates.md): none observed here,
        # and the table says how many pairs were left out and why.
        durations = page.locator(f'section:has(table.estimates[data-robot="{robot["robot"]}"])')
        for d in robot["durations"]:
            assert d["observed"] == 0 and d["observed_median_minutes"] is None, d
            cells = durations.locator(f'tr[data-task-type="{d["task_type"]}"] td')
            expect(cells.nth(1)).to_have_text("0")
            expect(cells.nth(2)).to_have_text("—")
            n = d["left_out"]["together_without_at"]
            expect(cells.nth(4)).to_have_text(f"{n} sent in one request without both times (at)")
    assert sum(len(r["durations"]) for r in api["robots"]) > 0
    marked = [
        (r["robot"], f["feature"]) for r in api["robots"] for f in r["features"] if f["marked"]
    ]
    assert ("heavy", "heavy") in marked
    expect(page.locator("#far-from-configured")).to_contain_text("heavy · heavy")
    expect(page.locator("svg#chart-rates")).to_be_visible()
    expect(page.locator("svg#chart-reliability")).to_be_visible()
    bins = page.locator("table#reliability tbody tr")
    expect(bins).to_have_count(len(api["reliability"]))
    assert _serious_violations(page) == []

    # The run's page leads to its site too; the sites list names it.
    page.goto(f"{server.url}/console/runs/{run_id}")
    expect(page.locator("#run-site a")).to_have_attribute("href", "/console/sites/yard-7")
    page.goto(f"{server.url}/console/sites")
    expect(page.locator("table#sites")).to_contain_text("yard-7")
    assert _serious_violations(page) == []
