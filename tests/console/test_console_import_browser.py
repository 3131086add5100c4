"""The console's "Import a schedule" page (docs/exchange.md#the-console-page) in a real
browser against a real server: reached from the navigation, a file uploaded with a site's
rates, its tasks, links, robots and skipped items shown as the API answers them, "Start a
run" planning it; a draft with a typed link is shown with its type and lag and starts a run
that honours it; a wrong file is refused with why; axe-clean."""

from __future__ import annotations

from typing import Any

import pytest
from playwright.sync_api import Page, expect

from tests.console.test_console_browser import _serious_violations
from tests.support.browser import CLIENT_KEY, sign_in, start_run, wait_status
from tests.support.exchange_files import small_mspdi
from tests.support.server import Server

pytestmark = pytest.mark.e2e

HEADERS = {"X-API-Key": CLIENT_KEY}
SITE = "fit-out-3"


@pytest.fixture(scope="module")
def site(server: Server) -> str:
    """A site with learned rates for the file's robots (heavy, light): a baseline run on it
    with two reports."""
    run_id = start_run(server, site=SITE)
    wait_status(server, run_id)
    with server.client() as c:
        sent = c.post(
            f"/runs/{run_id}/execution",
            json={"updates": [{"task_id": 0, "state": "started"}, {"task_id": 0, "state": "done"}]},
            headers=HEADERS,
        )
        assert sent.status_code == 200, sent.text
    return SITE


def _api_import(server: Server, data: bytes, **params: str) -> Any:
    with server.client() as c:
        answer = c.post("/schedules/import", content=data, params=params, headers=HEADERS)
    assert answer.status_code == 200, answer.text
    return answer.json()


def _upload(page: Page, data: bytes, name: str, site: str | None = None) -> None:
    page.get_by_label("Schedule file").set_input_files(
        {"name": name, "mimeType": "application/xml", "buffer": data}
    )
    if site is not None:
        page.get_by_label("Rates from a site").select_option(site)
    with page.expect_navigation():
        page.get_by_role("button", name="Import").click()


def test_a_file_imported_with_a_sites_rates_starts_a_run(
    page: Page, server: Server, site: str
) -> None:
    sign_in(page, server)
    page.get_by_role("navigation", name="Console").get_by_role(
        "link", name="Import a schedule"
    ).click()
    expect(page.get_by_role("heading", name="Import a schedule", level=1)).to_be_visible()
    assert _serious_violations(page) == []

    data = small_mspdi()
    _upload(page, data, "fit-out.xml", site)
    api = _api_import(server, data, site=site)
    rows = page.locator("#draft-tasks tbody tr")
    expect(rows).to_have_count(len(api["tasks"]))
    for i, task in enumerate(api["tasks"]):
        cells = rows.nth(i)
        expect(cells.locator("th")).to_have_text(task["id"])
        expect(cells.locator("td").nth(0)).to_have_text(task["name"])
        expect(cells.locator("td").nth(2)).to_have_text(str(task["duration"]))
        after = "; ".join(f"{a['task']} {a['type']}" for a in task["after"]) or "—"
        expect(cells.locator("td").nth(3)).to_have_text(after)
    for robot in api["robots"]:
        cell = page.locator(f'#draft-robots tr[data-robot="{robot["name"]}"] td')
        for feature, rate in robot["success"].items():
            expect(cell).to_contain_text(f"{feature} {100 * rate:.1f}%")
    expect(page.locator("#draft-robots caption")).to_contain_text(f"site {site}")
    expect(page.locator("#draft-skipped")).to_contain_text("Everything in the file was imported")
    expect(page.locator("#source")).to_contain_text("Level 3 fit-out")
    assert _serious_violations(page) == []

    with page.expect_navigation():
        page.get_by_role("button", name="Start a run").click()
    assert "/console/runs/" in page.url
    run_id = page.url.rsplit("/", 1)[-1]
    wait_status(server, run_id)
    with server.client() as c:
        state = c.get(f"/runs/{run_id}", headers=HEADERS).json()
    assert state["site"] == site
    assert sorted(str(a["task_id"]) for a in state["assignments"]) == ["1", "2", "3"]


def test_a_typed_link_is_shown_and_its_run_honours_it(
    page: Page, server: Server, site: str
) -> None:
    sign_in(page, server, then="/console/import")
    _upload(page, small_mspdi(typed=True), "typed.xml", site)
    expect(page.locator("#draft-tasks tbody tr").nth(1).locator("td").nth(3)).to_have_text(
        "1 SS +20 min"
    )
    assert _serious_violations(page) == []
    with page.expect_navigation():
        page.get_by_role("button", name="Start a run").click()
    run_id = page.url.rsplit("/", 1)[-1]
    wait_status(server, run_id)
    with server.client() as c:
        rows = c.get(f"/runs/{run_id}/schedule", headers=HEADERS).json()["tasks"]
    starts = {str(r["task_id"]): r["start"] for r in rows}
    assert starts["2"] >= starts["1"] + 20  # docs/schedules.md#links: SS +20


def test_without_rates_or_with_a_wrong_file_nothing_starts(page: Page, server: Server) -> None:
    sign_in(page, server, then="/console/import")
    _upload(page, small_mspdi(), "fit-out.xml")
    expect(page.locator("#unrated-note")).to_contain_text("No robot has a rate for")
    expect(page.get_by_role("button", name="Start a run")).to_have_count(0)
    page.goto(f"{server.url}/console/import")
    _upload(page, b'{"tasks": []}', "plan.json")
    expect(page.get_by_role("heading", name="Not imported")).to_be_visible()
    expect(page.get_by_role("alert")).to_contain_text("expected an MSPDI file")
    expect(page.get_by_role("link", name="Back")).to_have_attribute("href", "/console/import")
