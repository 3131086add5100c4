"""The run page's revisions and diff through the in-process client, for the cases a
browser test would take long to set up: a lineage of three, long diff lists cut short, a
revision whose parent's rows are gone, an archived run's page."""

from __future__ import annotations

import re
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.console import views
from app.store.models import ArchivedRun, Run
from tests.plans.test_revisions import HEAVY_DOWN, completed_run, revise, wait_status

BACK = {
    "changes": [{"type": "robot_available", "robot": "heavy"}],
    "pin": {"through_task_index": 20},
    "reason": "heavy repaired",
}


def _text(html: str) -> str:
    return re.sub(r"\s+", " ", re.sub(r"<[^>]+>", " ", html))


def _revised(client: TestClient, run_id: str, body: dict[str, Any]) -> str:
    created = str(revise(client, run_id, body)["id"])
    wait_status(client, created, "completed")
    return created


def test_a_lineage_of_three_from_its_middle(client: TestClient) -> None:
    root = completed_run(client)
    middle = _revised(client, root, HEAVY_DOWN)
    head = _revised(client, middle, BACK)

    page = client.get(f"/console/runs/{middle}")
    assert page.status_code == 200
    text = _text(page.text)
    # Revised itself: the notice leads to the head.
    assert "the current plan is revision 2 (completed)" in text
    assert f'href="/console/runs/{head}">revision 2</a>' in page.text
    # The lineage, oldest first, this run marked; each revision with its reason.
    rows = re.findall(r"<tr[^>]*>.*?</tr>", page.text.split('id="lineage"')[1], flags=re.S)
    body = [_text(r) for r in rows[1:4]]
    assert body[0].startswith(" original ") and "heavy robot hydraulic fault" in body[1]
    assert "(this run)" in body[1] and 'aria-current="true"' in rows[2]
    assert "heavy repaired" in body[2] and "robot available heavy" in body[2]
    # Its diff is against the original; the head's against revision 1.
    assert "What changed against the original plan" in text
    head_page = _text(client.get(f"/console/runs/{head}").text)
    assert "What changed against revision 1" in head_page
    assert "Revision 2 of the original plan : heavy repaired" in head_page
    # Without script each part is a page of its own, leading back to the run.
    for part, heading in (("diff", f"Revision {head} against its parent"), ("verify", "")):
        alone = client.get(f"/console/runs/{head}/{part}")
        assert alone.status_code == 200 and "<h1>" in alone.text
        assert (
            heading in alone.text and f'href="/console/runs/{head}">Back to the run' in alone.text
        )
    assert "What changed against revision 1" in _text(client.get(f"/console/runs/{head}/diff").text)


def test_long_diff_lists_are_cut_and_say_so(
    client: TestClient, monkeypatch: pytest.MonkeyPatch
) -> None:
    parent = completed_run(client)
    added = [{"id": f"N{i}", "name": f"new {i}", "features": ["heavy"]} for i in range(5)]
    revision = _revised(
        client,
        parent,
        {"changes": [{"type": "add_tasks", "tasks": added}], "pin": "decided", "reason": "more"},
    )
    monkeypatch.setattr(views, "DIFF_ROWS", 2)
    part = client.get(f"/console/runs/{revision}/diff", params={"fragment": 1})
    assert part.status_code == 200
    text = _text(part.text)
    assert "Tasks added (5)" in text
    assert "N0, N1 … and 3 more" in text
    assert "N2" not in text


def test_a_revision_whose_parent_is_gone_says_so(client: TestClient) -> None:
    parent = completed_run(client)
    revision = _revised(client, parent, HEAVY_DOWN)
    # As an archive racing a revision could leave it (before the archive re-checked): the
    # parent's rows gone, its tombstone in place.
    sessions = client.app.state.runs.sessions  # type: ignore[attr-defined]
    with sessions.begin() as session:
        row = session.get(Run, parent)
        session.add(
            ArchivedRun(
                id=parent,
                lineage_head=parent,
                archive_file=f"run-{parent}.jsonl",
                heads={},
                verified=True,
                status=row.status,
            )
        )
        session.delete(row)

    page = client.get(f"/console/runs/{revision}")
    assert page.status_code == 200
    assert 'id="diff-missing"' in page.text
    gone = client.get(f"/console/runs/{parent}")
    assert gone.status_code == 410
    assert f"run-{parent}.jsonl" in gone.text and "Archived" in gone.text


def test_a_plain_runs_diff_page_is_a_404_that_says_why(client: TestClient) -> None:
    run_id = completed_run(client)
    page = client.get(f"/console/runs/{run_id}")
    assert 'id="diff"' not in page.text and "This plan has not been revised" in page.text
    diff = client.get(f"/console/runs/{run_id}/diff")
    assert diff.status_code == 404 and "is not a revision" in diff.text
    assert client.get(f"/console/runs/{'0' * 32}/diff").status_code == 404
