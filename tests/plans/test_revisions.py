"""Revisions of completed runs through the API (docs/living-plans.md#revisions): the plan, the
record, the link."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.domain.catalog import scenario
from tests.audit.test_docs_check_trace import check_trace_source
from tests.support.clients import ClientFactory
from tests.support.offline_check import CHECK_TRACE, check_offline
from tests.support.polling import eventually

ROOT = Path(__file__).resolve().parents[2]
BASELINE = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
HEAVY_DOWN = {
    "changes": [{"type": "robot_unavailable", "robot": "heavy"}],
    "pin": {"through_task_index": 17},
    "reason": "heavy robot hydraulic fault",
}


def wait_status(client: TestClient, run_id: str, *statuses: str) -> dict[str, Any]:
    def reached(state: dict[str, Any]) -> bool:
        assert state["status"] not in ("failed", "cancelled"), state  # never completes now
        return state["status"] in statuses

    state: dict[str, Any] = eventually(
        lambda: client.get(f"/runs/{run_id}").json(),
        until=reached,
        what=f"run {run_id} reached {' or '.join(statuses)}",
    )
    return state


def wait_allocated(client: TestClient, run_id: str, count: int) -> None:
    eventually(
        lambda: client.get(f"/runs/{run_id}").json()["progress"]["allocated"],
        until=lambda allocated: allocated >= count,
        what=f"run {run_id} decided {count} tasks",
    )


def completed_run(client: TestClient, body: dict[str, Any] | None = None) -> str:
    run_id = str(client.post("/runs", json=body or BASELINE).json()["id"])
    wait_status(client, run_id, "completed")
    return run_id


def revise(client: TestClient, run_id: str, body: dict[str, Any], code: int = 202) -> Any:
    response = client.post(f"/runs/{run_id}/revisions", json=body)
    assert response.status_code == code, response.text
    return response.json()


def test_a_completed_parent_revised_stays_completed_and_still_verifies(
    client: TestClient,
) -> None:
    parent = completed_run(client)
    created = revise(client, parent, HEAVY_DOWN)
    assert created["revision_of"] == parent and created["revision"] == 1
    revision = wait_status(client, created["id"], "completed")
    before = client.get(f"/runs/{parent}").json()
    assert before["status"] == "completed" and before["superseded_by"] == created["id"]
    assert revision["revision_of"] == parent
    pinned = [a for a in revision["assignments"] if a["pinned"]]
    assert [a["task_index"] for a in pinned] == list(range(18))
    assert [(a["robot"], a["success"]) for a in pinned] == [
        (a["robot"], a["success"]) for a in before["assignments"][:18]
    ]
    assert all(a["robot"] != "heavy" for a in revision["assignments"] if not a["pinned"])
    for run_id in (parent, created["id"]):
        report = client.get(f"/runs/{run_id}/trace/verify").json()
        assert report["ok"] is True, report
        # A revision's chains, like any new run's, also cover its immutable fields.
        assert report["chain_scheme"] == "ltaa-trace-chain/v2", report
    link = client.get(f"/runs/{created['id']}/trace/verify").json()["parent"]
    assert link["run_id"] == parent and link["ok"] is True
    assert client.get(f"/runs/{parent}/trace/verify").json()["annotations"] == 1
    # The revision's trace: `revised` first, naming the parent's heads at that moment.
    trace = client.get(f"/runs/{created['id']}/trace").json()
    first = trace["events"][0]
    assert first["kind"] == "revised" and first["detail"]["parent"] == parent
    heads = client.get(f"/runs/{parent}/trace/verify").json()["heads"]
    assert first["detail"]["parent_heads"] == heads
    lineage = client.get(f"/runs/{created['id']}/revisions").json()
    assert [r["id"] for r in lineage] == [parent, created["id"]]
    diff = client.get(f"/runs/{created['id']}/diff").json()
    assert diff["parent"] == parent
    assert diff["fleet_changes"] == [{"robot": "heavy", "change": "unavailable"}]
    moved = {c["task_id"] for c in diff["robot_changes"]}
    was_heavy = {a["task_id"] for a in before["assignments"][18:] if a["robot"] == "heavy"}
    assert was_heavy and was_heavy <= moved
    assert all(c["to_robot"] != "heavy" for c in diff["robot_changes"])
    assert abs(diff["before"]["expected_success"] - before["metrics"]["expected_success"]) < 1e-9
    assert abs(diff["after"]["expected_success"] - revision["metrics"]["expected_success"]) < 1e-9
    # A second revision of the same run is a 409 naming the head.
    again = client.post(f"/runs/{parent}/revisions", json=HEAVY_DOWN)
    assert again.status_code == 409 and created["id"] in again.text


def test_a_revised_completed_parent_still_replays(client: TestClient) -> None:
    parent = completed_run(client)
    revision = revise(client, parent, HEAVY_DOWN)["id"]
    wait_status(client, revision, "completed")
    assert (
        client.post(
            f"/runs/{parent}/execution", json={"updates": [{"task_id": 0, "state": "done"}]}
        ).status_code
        == 409
    )
    replay = client.post("/runs", json={"reasoner": "replay", "replay_of": parent})
    assert replay.status_code == 202, replay.text
    replayed = wait_status(client, replay.json()["id"], "completed")
    original = client.get(f"/runs/{parent}").json()
    assert [a["robot"] for a in replayed["assignments"]] == [
        a["robot"] for a in original["assignments"]
    ]
    assert client.get(f"/runs/{parent}/trace/verify").json()["ok"] is True
    of_revision = client.post("/runs", json={"reasoner": "replay", "replay_of": revision})
    assert of_revision.status_code == 422 and "revision" in of_revision.text


def test_idempotent_revision_and_a_superseded_run_cannot_resume(
    make_client: ClientFactory,
) -> None:
    client = make_client(test_pause="18:reason:before")
    parent = str(client.post("/runs", json=BASELINE).json()["id"])
    wait_allocated(client, parent, 18)
    key = {"Idempotency-Key": "revise-once"}
    first = client.post(f"/runs/{parent}/revisions", json=HEAVY_DOWN, headers=key)
    again = client.post(f"/runs/{parent}/revisions", json=HEAVY_DOWN, headers=key)
    assert first.status_code == again.status_code == 202, again.text
    assert again.json()["id"] == first.json()["id"]
    assert again.headers["Idempotent-Replayed"] == "true"
    other = client.post(
        f"/runs/{parent}/revisions", json={**HEAVY_DOWN, "reason": "another"}, headers=key
    )
    assert other.status_code == 409
    state = client.get(f"/runs/{parent}").json()
    assert state["status"] == "superseded" and state["progress"]["allocated"] == 18
    resume = client.post(f"/runs/{parent}/resume")
    assert resume.status_code == 409 and first.json()["id"] in resume.text
    cancel = client.post(f"/runs/{parent}/cancel")
    assert cancel.status_code == 409
    assert len(client.get(f"/runs/{parent}/revisions").json()) == 2


def test_a_run_awaiting_review_revised_is_superseded_and_its_review_closed(
    client: TestClient,
) -> None:
    # Only task 202 (queue position 17) needs a review: the run pauses after 17 decisions.
    body = {**BASELINE, "review": {"task_ids": [202]}}
    parent = str(client.post("/runs", json=body).json()["id"])
    state = wait_status(client, parent, "awaiting_review")
    decided = state["progress"]["allocated"]
    pending = [r for r in client.get("/reviews").json() if r["run_id"] == parent]
    assert len(pending) == 1
    created = revise(client, parent, {**HEAVY_DOWN, "pin": "decided"})
    after = client.get(f"/runs/{parent}").json()
    assert after["status"] == "superseded" and after["superseded_by"] == created["id"]
    assert [r for r in client.get("/reviews").json() if r["run_id"] == parent] == []
    kinds = [e["kind"] for e in client.get(f"/runs/{parent}/trace").json()["events"]]
    assert kinds[-2:] == ["review_closed", "superseded"]
    task_index = pending[0]["task_index"]
    late = client.post(f"/runs/{parent}/reviews/{task_index}", json={"action": "approve"})
    assert late.status_code == 409
    revision = client.get(f"/runs/{created['id']}").json()
    assert sum(a["pinned"] for a in revision["assignments"]) == decided
    assert client.get(f"/runs/{created['id']}/trace/verify").json()["parent"]["ok"] is True


@pytest.mark.parametrize(
    "pin",
    [
        {"through_task_index": 17},
        # Pins that are not the first tasks: chained first all the same, and so exported.
        "task_ids",
    ],
)
def test_a_revisions_export_verifies_offline_and_a_forged_link_does_not(
    client: TestClient, tmp_path: Path, pin: Any
) -> None:
    """scripts/check_trace.py and the docs' snippet check a revision's export as trace/verify
    checks the revision; an export whose link was edited (another reason than the one its
    chains were anchored to) is refused."""
    parent = completed_run(client)
    if pin == "task_ids":
        ids = [a["task_id"] for a in client.get(f"/runs/{parent}").json()["assignments"]]
        pin = {"task_ids": [ids[5], ids[9], ids[30]]}
    created = revise(client, parent, {**HEAVY_DOWN, "pin": pin})
    wait_status(client, created["id"], "completed")
    text = client.get(f"/runs/{created['id']}/trace", params={"format": "jsonl"}).text
    export = tmp_path / "revision.jsonl"
    export.write_text(text)
    heads = client.get(f"/runs/{created['id']}/trace/verify").json()["heads"]
    snippet = tmp_path / "check_trace_snippet.py"
    snippet.write_text(check_trace_source())
    for script in (CHECK_TRACE, snippet):
        done = check_offline(export, script=script)
        assert done.returncode == 0, done.stdout + done.stderr
        assert heads["decisions"] in done.stdout and heads["events"] in done.stdout

    lines = [json.loads(line) for line in text.splitlines()]
    first = next(line for line in lines if line["type"] == "event")
    assert first["kind"] == "revised"
    first["detail"]["reason"] = "nothing happened"
    export.write_text("".join(json.dumps(line) + "\n" for line in lines))
    forged = check_offline(export)
    assert forged.returncode == 1, forged.stdout + forged.stderr


def test_a_pinned_decision_keeps_the_supervisors_override(client: TestClient) -> None:
    task = scenario("baseline").instance.tasks[5]
    run_id = client.post("/runs", json={**BASELINE, "review": {"task_ids": [task.id]}}).json()["id"]
    wait_status(client, run_id, "awaiting_review")
    (pending,) = [r for r in client.get("/reviews").json() if r["run_id"] == run_id]
    other = next(
        a["robot"]
        for a in pending["alternatives"]
        if a["robot"] != pending["proposal"]["robot"] and a["cap_feasible"]
    )
    resolved = client.post(
        f"/runs/{run_id}/reviews/5",
        json={"action": "override", "robot": other, "reason": "crane access from the north"},
    )
    assert resolved.status_code == 200, resolved.text
    wait_status(client, run_id, "completed")
    created = revise(client, run_id, HEAVY_DOWN)
    wait_status(client, created["id"], "completed")
    trace = client.get(f"/runs/{created['id']}/trace").json()
    five = trace["decisions"][5]
    assignment = client.get(f"/runs/{created['id']}").json()["assignments"][5]
    assert assignment["pinned"] is True and assignment["robot"] == five["robot"] == other
    assert five["review"]["action"] == "override"
    assert five["review"]["reason"] == "crane access from the north"
    assert client.get(f"/runs/{created['id']}/trace/verify").json()["ok"] is True


def test_the_trace_and_the_export_say_which_decisions_a_revision_kept(
    client: TestClient,
) -> None:
    # A supervisor auditing a revision tells kept decisions from new ones: in the trace, in
    # the assignments and in the JSON-lines export, each pin names the parent decision.
    parent = completed_run(client)
    pins = {"type": "robot_unavailable", "robot": "heavy"}
    body = {"changes": [pins], "pin": {"task_ids": [2, 13, 300]}, "reason": "audit"}
    created = revise(client, parent, body)
    wait_status(client, created["id"], "completed")
    parent_hashes = {
        line["task_index"]: line["chain_hash"]
        for line in map(json.loads, client.get(f"/runs/{parent}/trace?format=jsonl").iter_lines())
        if line["type"] == "decision"
    }
    kept = {2: parent_hashes[2], 13: parent_hashes[13], 14: parent_hashes[14]}  # 300 is index 14
    trace = client.get(f"/runs/{created['id']}/trace").json()
    assert len(trace["decisions"]) == 36
    assert {d["task_index"]: d["pinned_from"] for d in trace["decisions"] if d["pinned"]} == kept
    assert all(d["pinned_from"] is None for d in trace["decisions"] if not d["pinned"])
    run = client.get(f"/runs/{created['id']}").json()
    assert {a["task_index"]: a["pinned_from"] for a in run["assignments"] if a["pinned"]} == kept
    export = [
        line
        for line in map(
            json.loads, client.get(f"/runs/{created['id']}/trace?format=jsonl").iter_lines()
        )
        if line["type"] == "decision"
    ]
    assert {d["task_index"]: d["pinned_from"] for d in export if d.get("pinned")} == kept
    assert not any("pinned_from" in d for d in export if not d.get("pinned"))
    assert client.get(f"/runs/{created['id']}/trace/verify").json()["ok"] is True
