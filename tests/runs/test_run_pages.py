"""GET /runs/{id} keeps each stored assignment as rendered (app.runs.pages): the answers
are the bytes the whole RunOut renders to, page by page, while the run grows and after an
execution report changes one assignment."""

from __future__ import annotations

from fastapi.testclient import TestClient

from app.http.rounding import RoundedJSONResponse
from app.runs import views
from app.runs.endpoints import _assignment, _run_head
from tests.plans.test_revisions import BASELINE, wait_allocated, wait_status
from tests.support.clients import ClientFactory
from tests.support.polling import eventually


def _rendered_whole(client: TestClient, run_id: str, offset: int, limit: int) -> bytes:
    """What the route answered before it kept anything: every assignment of the page
    rendered with the rest of RunOut, in one piece."""
    runs = client.app.state.runs  # type: ignore[attr-defined]
    view = views.run_view(sessions=runs.sessions, run_id=run_id, offset=offset, limit=limit)
    out = _run_head(view, limit)
    out.assignments = [_assignment(view, d) for d in view.decisions]
    return bytes(RoundedJSONResponse(out.model_dump(mode="json")).body)


def _poll(client: TestClient, run_id: str, offset: int = 0, limit: int = 1000) -> bytes:
    answer = client.get(f"/runs/{run_id}", params={"offset": offset, "limit": limit})
    assert answer.status_code == 200 and answer.headers["content-type"] == "application/json"
    return answer.content


def test_kept_assignments_answer_what_the_whole_page_renders_to(
    make_client: ClientFactory,
) -> None:
    client = make_client(test_pause="20:reason:before")
    run_id = str(client.post("/runs", json=BASELINE).json()["id"])
    wait_allocated(client, run_id, 20)  # held before task 20: the page stops growing
    first = _poll(client, run_id)
    assert first == _rendered_whole(client, run_id, 0, 1000)
    assert _poll(client, run_id) == first  # now from what was kept
    assert len(client.get(f"/runs/{run_id}").json()["assignments"]) == 20
    # Pages that begin and end inside what was kept, and a page past it.
    for offset, limit in ((5, 7), (0, 3), (19, 10), (30, 10)):
        assert _poll(client, run_id, offset, limit) == _rendered_whole(
            client, run_id, offset, limit
        )

    # An execution report moves one assignment: the next poll shows it.
    reported = client.post(
        f"/runs/{run_id}/execution", json={"updates": [{"task_id": 3, "state": "started"}]}
    )
    assert reported.status_code == 200, reported.text
    after = client.get(f"/runs/{run_id}").json()["assignments"]
    assert after[3]["execution"]["state"] == "started"
    assert [a["execution"] for i, a in enumerate(after) if i != 3] == [None] * 19
    assert _poll(client, run_id) == _rendered_whole(client, run_id, 0, 1000)

    cancelled = client.post(f"/runs/{run_id}/cancel")
    assert cancelled.status_code == 200, cancelled.text
    assert cancelled.json()["assignments"] == client.get(f"/runs/{run_id}").json()["assignments"]
    eventually(
        lambda: client.get(f"/runs/{run_id}").json()["status"],
        until=lambda status: status == "cancelled",
        what=f"run {run_id} cancelled",
    )
    assert _poll(client, run_id) == _rendered_whole(client, run_id, 0, 1000)


def test_a_completed_run_answers_the_same_before_and_after_its_page_is_kept(
    make_client: ClientFactory,
) -> None:
    client = make_client()
    run_id = str(client.post("/runs", json=BASELINE).json()["id"])
    wait_status(client, run_id, "completed")
    warm = _poll(client, run_id)
    assert warm == _poll(client, run_id) == _rendered_whole(client, run_id, 0, 1000)
    assert len(client.get(f"/runs/{run_id}").json()["assignments"]) == 36
