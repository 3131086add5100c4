"""Revisions on the console's run page (docs/living-plans.md#in-the-console): the lineage with
each revision's reason, changes and pins, and the revision against its parent as the JSON
diff states it; a large revision's diff is fetched by the page after it loads."""

from __future__ import annotations

from typing import Any

import pytest
from playwright.sync_api import Page, expect

from tests.console.test_console_browser import _serious_violations
from tests.support.browser import CLIENT_KEY, sign_in, start_run, tasks, wait_status
from tests.support.server import Server

pytestmark = pytest.mark.e2e

HEADERS = {"X-API-Key": CLIENT_KEY}


def _revise(server: Server, run_id: str, body: dict[str, Any]) -> str:
    with server.client() as c:
        created = c.post(f"/runs/{run_id}/revisions", json=body, headers=HEADERS)
    assert created.status_code == 202, created.text
    return str(created.json()["id"])


def _json(server: Server, path: str) -> Any:
    with server.client() as c:
        answer = c.get(path, headers=HEADERS)
    assert answer.status_code == 200, answer.text
    return answer.json()


def _pct(value: float, digits: int) -> str:
    return f"{100 * value:.{digits}f}%"


def test_a_revision_page_shows_the_lineage_and_the_diff_the_api_states(
    page: Page, server: Server
) -> None:
    parent = start_run(server)
    wait_status(server, parent)
    reason = "heavy lifter down for a hydraulic repair"
    revision = _revise(
        server,
        parent,
        {
            "changes": [{"type": "robot_unavailable", "robot": "heavy"}],
            "pin": {"through_task_index": 17},
            "reason": reason,
        },
    )
    wait_status(server, revision)
    diff = _json(server, f"/runs/{revision}/diff")
    assert diff["robot_changes"], "taking a robot away moved no task: nothing to show"

    # The runs list says which plan each run is.
    sign_in(page, server)
    expect(page.locator(f'tr[data-run="{revision}"] td.plan')).to_have_text("revision 1")
    expect(page.locator(f'tr[data-run="{parent}"] td.plan')).to_have_text("original, revised")
    link = page.locator(f'tr[data-run="{parent}"] td.plan a')
    expect(link).to_have_attribute("href", f"/console/runs/{revision}")

    # The parent's page says it was revised and leads to the current plan.
    page.goto(f"{server.url}/console/runs/{parent}")
    notice = page.locator("#superseded-notice")
    expect(notice).to_contain_text("revision 1")
    notice.get_by_role("link", name="revision 1").click()
    expect(page).to_have_url(f"{server.url}/console/runs/{revision}")

    # The lineage: the original, then this revision with its reason, change and 18 pins.
    rows = page.locator("table#lineage tbody tr")
    expect(rows).to_have_count(2)
    expect(rows.nth(0)).to_contain_text("original")
    expect(rows.nth(0).get_by_role("link")).to_have_attribute("href", f"/console/runs/{parent}")
    current = rows.nth(1)
    expect(current).to_have_attribute("aria-current", "true")
    expect(current).to_contain_text(reason)
    expect(current).to_contain_text("robot unavailable heavy")
    expect(current.locator("td").nth(6)).to_have_text("18")

    # The diff, as GET /runs/{id}/diff states it.
    box = page.locator("#diff")
    metrics = box.locator("table.diff-metrics tbody tr")
    expect(metrics.nth(0).locator("td")).to_have_text(
        [_pct(diff["before"]["expected_success"], 2), _pct(diff["after"]["expected_success"], 2)]
    )
    expect(metrics.nth(1).locator("td")).to_have_text(
        [f"{diff['before']['balance_score']:,.1f}", f"{diff['after']['balance_score']:,.1f}"]
    )
    expect(box.locator("#diff-fleet")).to_have_text("heavy: unavailable")
    moves = box.locator("table.diff-moves tbody tr")
    expect(moves).to_have_count(len(diff["robot_changes"]))
    for i, change in enumerate(diff["robot_changes"]):
        row = moves.nth(i)
        expect(row).to_have_attribute("data-task", str(change["task_id"]))
        expect(row.locator("td")).to_have_text(
            [
                change["from_robot"],
                change["to_robot"],
                _pct(change["success_before"], 1),
                _pct(change["success_after"], 1),
            ]
        )
        assert change["to_robot"] != "heavy"
    assert _serious_violations(page) == []


@pytest.mark.timeout(900)
def test_a_large_revisions_diff_is_fetched_after_the_page_and_a_plain_run_has_none(
    page: Page, server: Server
) -> None:
    body = tasks(1001)  # past the page's inline limit (app.console.views.INLINE_TASKS)
    parent = start_run(server, **body)
    # 1,001 durable tasks: 120 s was not enough beside three busy workers on a loaded machine.
    wait_status(server, parent, timeout=300)
    revision = _revise(
        server,
        parent,
        {
            "changes": [
                {
                    "type": "add_tasks",
                    "tasks": [{"id": "T-extra", "name": "late slab", "features": ["heavy"]}],
                }
            ],
            "pin": "decided",
            "reason": "a slab added at the end",
        },
    )
    wait_status(server, revision, timeout=120)
    sign_in(page, server, then=f"/console/runs/{revision}")
    box = page.locator("#diff")
    expect(box).to_have_attribute("data-load", f"/console/runs/{revision}/diff?fragment=1")
    expect(box.locator("#diff-added")).to_have_text("T-extra", timeout=30_000)
    expect(box.locator("table.diff-moves tbody")).to_contain_text("No decided task changed robot")

    # A run that is no revision: no diff on its page, and its diff page says why.
    page.goto(f"{server.url}/console/runs/{parent}")
    expect(page.locator("#diff")).to_have_count(0)
    answer = page.goto(f"{server.url}/console/runs/{parent}/diff")
    assert answer is not None and answer.status == 404
    expect(page.get_by_role("main")).to_contain_text("is not a revision")
