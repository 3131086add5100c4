"""What GET /runs/{id} says of a timed revision's plan (docs/living-plans.md#a-revision-in-time):
a team task added with a deadline no robot can meet is planned late and the answer says so, as
POST /allocate does (`schedule_violations`); pins the site had not reported show the times the
revision placed them at, the same as its schedule, on every poll."""

from __future__ import annotations

from typing import Any

from fastapi.testclient import TestClient

from tests.plans.test_revisions import BASELINE, completed_run, revise, wait_status
from tests.plans.test_timed_team_revisions import at, completed

EXTRA = {"id": "extra", "name": "Extra", "features": ["careful"], "duration": 5, "zone": "south"}


def _times(schedule: dict[str, Any]) -> dict[str, tuple[float, float]]:
    return {str(t["task_id"]): (t["start"], t["end"]) for t in schedule["tasks"]}


def test_a_team_task_added_with_a_deadline_nobody_meets_is_reported_late(
    client: TestClient,
) -> None:
    parent = completed(client)
    assert parent["schedule_violations"] == []  # the plan breaks nothing
    # 15 minutes due by minute 20, added at minute 10: no chain makes it impossible (the
    # request is accepted), the clock does.
    mast = {"id": "mast", "name": "Raise mast", "team": {"heavy": 2}, "duration": 15}
    mast |= {"zone": "north", "deadline": 20}
    created = revise(
        client,
        parent["id"],
        {"now": at(10), "changes": [{"type": "add_tasks", "tasks": [mast]}], "reason": "mast"},
    )
    revision = wait_status(client, created["id"], "completed")
    planned = {a["task_id"]: a for a in revision["assignments"]}["mast"]
    assert planned["end"] > 20  # planned late
    missed = [v for v in revision["schedule_violations"] if v["task_id"] == "mast"]
    assert [v["rule"] for v in missed] == ["deadline"]
    assert "deadline" in missed[0]["message"]


def test_an_untimed_run_reports_no_schedule_violations(client: TestClient) -> None:
    run_id = completed_run(client, BASELINE)
    assert "schedule_violations" not in client.get(f"/runs/{run_id}").json()


def test_unreported_pins_show_the_times_the_revision_placed_them_at(
    client: TestClient,
) -> None:
    parent = completed(client)
    created = revise(
        client,
        parent["id"],
        {
            "now": at(0),
            "pin": "decided",
            "changes": [{"type": "add_tasks", "tasks": [EXTRA]}],
            "reason": "one more",
        },
    )
    first = client.get(f"/runs/{created['id']}").json()  # maybe before it placed anything
    revision = wait_status(client, created["id"], "completed")
    schedule = _times(client.get(f"/runs/{created['id']}/schedule").json())
    pinned = [a for a in revision["assignments"] if a.get("pinned")]
    assert len(pinned) == 5 and first["id"] == created["id"]
    for a in pinned:
        assert a["start"] is not None and a["end"] is not None, a
        assert (a["start"], a["end"]) == schedule[str(a["task_id"])]
    again = client.get(f"/runs/{created['id']}").json()  # a poll that keeps what it rendered
    assert [a.get("start") for a in again["assignments"]] == [
        a.get("start") for a in revision["assignments"]
    ]
