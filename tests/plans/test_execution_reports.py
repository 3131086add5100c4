"""Execution reports (docs/living-plans.md#execution-reports): forward only, idempotent, only for
decided tasks, refused on a revised run, events while the run is unfinished and annotations after
(verify stays ok); and what `pin: "reported"` makes of them."""

from __future__ import annotations

import json
from typing import Any

import pytest
from fastapi.testclient import TestClient

from tests.plans.test_revisions import (
    BASELINE,
    completed_run,
    revise,
    wait_allocated,
    wait_status,
)
from tests.support.clients import ClientFactory


def report(client: TestClient, run_id: str, *updates: tuple[Any, str], **kw: Any) -> Any:
    body = {"updates": [{"task_id": t, "state": s} for t, s in updates]}
    return client.post(f"/runs/{run_id}/execution", json=body, **kw)


@pytest.fixture
def paused(make_client: ClientFactory) -> tuple[TestClient, str]:
    """A client whose runs hold before reasoning about task 18, and one such run."""
    client = make_client(test_pause="18:reason:before")
    run_id = str(client.post("/runs", json=BASELINE).json()["id"])
    wait_allocated(client, run_id, 18)
    return client, run_id


def test_states_move_forward_only_and_repeats_are_no_ops(client: TestClient) -> None:
    run_id = completed_run(client)
    assert report(client, run_id, (0, "started")).json()["states"] == {"0": "started"}
    assert report(client, run_id, (0, "started")).status_code == 200  # the same: a no-op
    assert report(client, run_id, (0, "done"), (1, "failed")).json()["states"] == {
        "0": "done",
        "1": "failed",
    }
    back = report(client, run_id, (0, "started"))
    assert back.status_code == 409
    assert back.json()["detail"][0]["loc"] == ["body", "updates", 0, "state"]
    assert "forward only" in back.text and "stale" in back.text
    assert report(client, run_id, (1, "done")).status_code == 409  # failed is final
    # One transaction: a refused update leaves the others unapplied.
    mixed = report(client, run_id, (2, "started"), (0, "started"))
    assert mixed.status_code == 409
    state = client.get(f"/runs/{run_id}").json()
    by_id = {a["task_id"]: a.get("execution") for a in state["assignments"]}
    assert by_id[0]["state"] == "done" and by_id[1]["state"] == "failed" and by_id[2] is None
    # After completion reports go to the annotation chain: the record still verifies.
    verify = client.get(f"/runs/{run_id}/trace/verify").json()
    assert verify["ok"] is True and verify["annotations"] == 2  # the no-op wrote nothing
    assert verify["events"] == 3


def test_unknown_and_undecided_tasks(paused: tuple[TestClient, str]) -> None:
    client, run_id = paused
    undecided = report(client, run_id, (205, "started"))  # queue position 20
    assert undecided.status_code == 409 and "'205'" in undecided.text
    assert undecided.json()["detail"][0]["loc"] == ["body", "updates", 0, "task_id"]
    unknown = report(client, run_id, ("nope", "done"))
    assert unknown.status_code == 422 and "'nope'" in unknown.text
    # While the run is unfinished a report is an event of its record.
    assert report(client, run_id, (0, "done")).status_code == 200
    kinds = [e["kind"] for e in client.get(f"/runs/{run_id}/trace").json()["events"]]
    assert kinds[-1] == "execution_reported"


def test_idempotency_key(client: TestClient) -> None:
    run_id = completed_run(client)
    key = {"Idempotency-Key": "exec-1"}
    first = report(client, run_id, (0, "started"), headers=key)
    assert first.status_code == 200
    assert report(client, run_id, (0, "started"), headers=key).json() == first.json()
    other = report(client, run_id, (0, "done"), headers=key)
    assert other.status_code == 409 and other.json()["detail"][0]["loc"] == [
        "header",
        "Idempotency-Key",
    ]


def test_a_revised_run_refuses_reports_naming_the_head(client: TestClient) -> None:
    run_id = completed_run(client)
    head = revise(client, run_id, {"changes": [], "pin": "decided", "reason": "re-plan"})["id"]
    refused = report(client, run_id, (0, "done"))
    assert refused.status_code == 409 and head in refused.text
    # The run id is in the path, not the body.
    assert refused.json()["detail"][0]["loc"] == ["path", "run_id"]
    assert refused.json()["detail"][0]["type"] == "revised"
    wait_status(client, head, "completed")
    assert report(client, head, (0, "done")).status_code == 200


def test_pin_reported_excludes_failed_and_started_on_an_unavailable_robot(
    paused: tuple[TestClient, str],
) -> None:
    client, run_id = paused
    state = client.get(f"/runs/{run_id}").json()
    robot = {a["task_id"]: a["robot"] for a in state["assignments"]}
    ids = [a["task_id"] for a in state["assignments"]]
    on_heavy = [t for t in ids if robot[t] == "heavy"]
    elsewhere = [t for t in ids if robot[t] != "heavy"]
    started_heavy, done_heavy = on_heavy[0], on_heavy[1]
    started_other, failed = elsewhere[0], elsewhere[1]
    done = elsewhere[2:5]
    updates = [
        (started_heavy, "started"),
        (done_heavy, "started"),
        (done_heavy, "done"),
        (started_other, "started"),
        (failed, "failed"),
        *((t, "done") for t in done),
    ]
    assert report(client, run_id, *updates).status_code == 200
    created = revise(
        client,
        run_id,
        {"changes": [{"type": "robot_unavailable", "robot": "heavy"}], "reason": "fault"},
    )
    revision = client.get(f"/runs/{created['id']}").json()
    pinned = {a["task_id"] for a in revision["assignments"] if a["pinned"]}
    assert pinned == {done_heavy, started_other, *done}
    assert client.get(f"/runs/{run_id}").json()["status"] == "superseded"
    assert client.get(f"/runs/{created['id']}/trace/verify").json()["parent"]["ok"] is True


def test_a_revision_keeps_the_reports_of_what_it_pinned_so_its_own_revision_does_too(
    client: TestClient,
) -> None:
    """The site reports to the head: a revision must carry where its pinned tasks stand, or
    revising it (pin "reported", the default) would plan again a task already done."""
    parent = completed_run(client)
    ids = [a["task_id"] for a in client.get(f"/runs/{parent}").json()["assignments"]]
    done, started, failed = ids[3], ids[7], ids[9]
    updates = [(done, "started"), (done, "done"), (started, "started"), (failed, "failed")]
    assert report(client, parent, *updates).status_code == 200
    first = revise(client, parent, {"changes": [], "reason": "re-plan the rest"})["id"]
    wait_status(client, first, "completed")
    state = {a["task_id"]: a for a in client.get(f"/runs/{first}").json()["assignments"]}
    assert {t for t, a in state.items() if a["pinned"]} == {done, started}
    assert state[done]["execution"]["state"] == "done"
    assert state[started]["execution"]["state"] == "started"
    assert state[failed]["execution"] is None  # re-planned: its old failure stays behind
    events = client.get(f"/runs/{first}/trace").json()["events"]
    assert events[0]["detail"]["execution"] == {str(done): "done", str(started): "started"}

    second = revise(client, first, {"changes": [], "reason": "and again"})["id"]
    wait_status(client, second, "completed")
    again = {a["task_id"]: a for a in client.get(f"/runs/{second}").json()["assignments"]}
    assert {t for t, a in again.items() if a["pinned"]} == {done, started}
    # The head accepts the rest of the story: started -> done.
    assert report(client, second, (started, "done")).status_code == 200
    assert client.get(f"/runs/{second}/trace/verify").json()["ok"] is True


def _timed(client: TestClient, run_id: str, *updates: tuple[Any, str, Any]) -> Any:
    body = {"updates": [{"task_id": t, "state": s, "at": at} for t, s, at in updates]}
    return client.post(f"/runs/{run_id}/execution", json=body)


def _execution(client: TestClient, run_id: str, task_id: Any) -> Any:
    state = client.get(f"/runs/{run_id}").json()
    return next(a["execution"] for a in state["assignments"] if a["task_id"] == task_id)


def test_a_time_with_an_offset_is_stored_and_shown_in_utc(client: TestClient) -> None:
    run_id = completed_run(client)
    answer = _timed(
        client,
        run_id,
        (0, "started", "2026-12-01T09:30:00+05:00"),
        (0, "done", "2026-12-01T01:15:00-06:00"),
    )
    assert answer.status_code == 200, answer.text
    shown = _execution(client, run_id, 0)
    assert shown["started_at"] == "2026-12-01T04:30:00Z"
    assert shown["ended_at"] == "2026-12-01T07:15:00Z"
    export = client.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text
    lines = [json.loads(line) for line in export.splitlines()]
    recorded = next(x["detail"]["updates"] for x in lines if "updates" in x.get("detail", {}))
    assert [u["at"] for u in recorded] == ["2026-12-01T04:30:00+00:00", "2026-12-01T07:15:00+00:00"]


@pytest.mark.parametrize(
    "at",
    [
        "2026-12-01T09:30:00",  # no offset: the site's local time, or UTC?
        "2026-12-01",
        1700000000,  # a bare number, which pydantic would take as seconds since 1970
        "1700000000",
        "0001-01-01T00:00:00+14:00",  # its UTC time is before year 1
        "9999-12-31T23:59:59-01:00",  # and this one after year 9999
    ],
)
def test_a_time_without_an_offset_or_out_of_range_is_a_422_naming_it(
    client: TestClient, at: Any
) -> None:
    run_id = completed_run(client)
    refused = _timed(client, run_id, (1, "started", "2026-12-01T09:30:00Z"), (0, "started", at))
    assert refused.status_code == 422, refused.text
    detail = refused.json()["detail"]
    assert [d["loc"] for d in detail] == [["body", "updates", 1, "at"]]
    assert "offset" in detail[0]["msg"] or "range" in detail[0]["msg"]
    assert _execution(client, run_id, 1) is None  # nothing half-written


def test_a_done_or_failed_time_before_the_started_time_is_a_422_naming_it(
    client: TestClient,
) -> None:
    run_id = completed_run(client)
    assert _timed(client, run_id, (0, "started", "2026-12-01T10:00:00Z")).status_code == 200
    # 10:00+05:00 is 05:00Z: earlier than the recorded start, although its digits are not.
    early = _timed(client, run_id, (0, "done", "2026-12-01T10:00:00+05:00"))
    assert early.status_code == 422, early.text
    detail = early.json()["detail"][0]
    assert detail["loc"] == ["body", "updates", 0, "at"]
    assert "2026-12-01T10:00:00" in detail["msg"] and "started" in detail["msg"]
    # Within one report: the start it reports counts, and nothing is applied.
    same = _timed(
        client,
        run_id,
        (1, "started", "2026-12-01T10:00:00Z"),
        (1, "failed", "2026-12-01T09:59:59Z"),
    )
    assert same.status_code == 422, same.text
    assert same.json()["detail"][0]["loc"] == ["body", "updates", 1, "at"]
    assert _execution(client, run_id, 1) is None
    assert _execution(client, run_id, 0)["state"] == "started"
    # The same instant as the start, or later, is fine.
    assert _timed(client, run_id, (0, "done", "2026-12-01T10:00:00Z")).status_code == 200
    assert _execution(client, run_id, 0)["ended_at"] == "2026-12-01T10:00:00Z"
