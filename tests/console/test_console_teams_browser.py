"""The console shows a team decision (docs/allocation.md#teams): a durable untimed run with team
tasks completes under the rules reasoner; its run page lists each team decision's members in
the decision list, the opened decision shows one line per unit with that member's reasoning
from the **Team** block, the workload chart counts every member, and axe finds nothing."""

from __future__ import annotations

import copy

import pytest
from axe_playwright_python.sync_playwright import Axe
from playwright.sync_api import Page, expect

from tests.allocation.test_api_teams import TEAM_BODY
from tests.support.browser import CLIENT_KEY, sign_in, start_run, wait_status
from tests.support.server import Server

pytestmark = pytest.mark.e2e


def _violations(page: Page) -> list[str]:
    results = Axe().run(page)
    return [f"{v['id']} ({v['impact']}): {v['help']}" for v in results.response["violations"]]


def test_a_team_runs_pages_show_each_member_with_its_reasoning(page: Page, server: Server) -> None:
    run_id = start_run(server, **copy.deepcopy(TEAM_BODY))
    wait_status(server, run_id)
    with server.client() as c:
        run = c.get(f"/runs/{run_id}", headers={"X-API-Key": CLIENT_KEY}).json()
    beam = run["assignments"][0]
    members = [(m["feature"], m["robot"]) for m in beam["team"]]
    assert [f for f, _ in members] == ["heavy", "heavy"]

    sign_in(page, server)
    page.goto(f"{server.url}/console/runs/{run_id}")
    summary = page.locator("#decision-0 summary")
    expect(summary).to_contain_text(" + ".join(r for _, r in members))
    expect(summary.locator(".badge", has_text="team")).to_be_visible()
    # A one-robot decision keeps its one name and no team table.
    expect(page.locator("#decision-2 summary")).not_to_contain_text("team")
    assert page.locator("#team-2").count() == 0
    # Every member counts in the workload figures (6 units over 4 tasks), as GET /runs/{id}.
    loads = ", ".join(f"{name} {n}" for name, n in run["workload"].items())
    expect(page.locator(".charts figcaption").first).to_have_text(f"Workload per robot: {loads}.")
    assert sum(run["workload"].values()) == 6, run["workload"]

    page.goto(f"{server.url}/console/runs/{run_id}?decision=0#decision-0")
    table = page.locator("#team-0")
    expect(table).to_be_visible()
    rows = table.locator("tbody tr")
    expect(rows).to_have_count(2)
    for i, (feature, robot) in enumerate(members):
        row = rows.nth(i)
        expect(row.locator("td").first).to_have_text(feature)
        expect(row.locator("th")).to_have_text(robot)
        # The rules reasoner's sentence for this member: `covers heavy at 90% with ...`.
        expect(row.locator(".member-reason")).to_contain_text(f"covers {feature} at")
    # Another team decision opens in place, its members (a heavy and a careful unit) listed.
    expect(page.locator("#team-1")).to_be_hidden()
    page.locator("#decision-1 summary").click()
    expect(page.locator("#team-1")).to_be_visible()
    expect(page.locator("#team-1 tbody tr")).to_have_count(2)
    expect(page.locator("#team-1 tbody tr td:first-child")).to_have_text(["heavy", "careful"])
    assert _violations(page) == []
