"""Revisions against the real server (docs/living-plans.md#revisions): a run paused at task 18 is
revised when the heavy robot fails; SIGKILLs right after the 202 and during the revision's own run
change nothing: one revision, the plan an uninterrupted revision makes, a record that verifies."""

from __future__ import annotations

import json
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.graph.pause import PausePoint
from tests.support.polling import eventually
from tests.support.server import Server

pytestmark = pytest.mark.e2e

GUIDED = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules", "guidance": "optimizer"}
HEAVY_DOWN = {
    "changes": [{"type": "robot_unavailable", "robot": "heavy"}],
    "pin": {"through_task_index": 17},
    "reason": "heavy robot hydraulic fault",
}
PAUSE = PausePoint(18, "reason", after=False)


def wait_for_log(server: Server, text: str, count: int = 1, timeout: float = 60.0) -> None:
    def seen() -> int:
        assert server.proc is not None and server.proc.poll() is None, server.log.read_text()
        return server.log.read_text().count(text)

    eventually(
        seen,
        until=lambda n: n >= count,
        timeout=timeout,
        what=f"the server logged {text!r} {count} time(s)",
        context=lambda: server.log.read_text()[-3000:],
    )


def finished(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def post(c: httpx.Client, url: str, body: dict[str, Any]) -> dict[str, Any]:
    response = c.post(url, json=body)
    assert response.status_code in (200, 202), response.text
    return dict(response.json())


def jsonl_decisions(c: httpx.Client, run_id: str) -> list[dict[str, Any]]:
    text = c.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text
    lines = [json.loads(line) for line in text.splitlines() if line]
    return [line for line in lines if line["type"] == "decision"]


def paused_parent(server: Server) -> str:
    with server.client() as c:
        parent = str(post(c, "/runs", GUIDED)["id"])
    wait_for_log(server, PAUSE.message())
    return parent


def uninterrupted_revision(server: Server) -> dict[str, Any]:
    """The reference: the same parent completed, then revised the same way, no kill."""
    with server.client() as c:
        parent = str(post(c, "/runs", GUIDED)["id"])
        server.wait_for(parent, finished)
        revision = str(post(c, f"/runs/{parent}/revisions", HEAVY_DOWN)["id"])
    return server.wait_for(revision, finished)


def plan(state: dict[str, Any]) -> list[tuple[Any, str]]:
    return [(a["task_id"], a["robot"]) for a in state["assignments"]]


def test_run_paused_at_18_revised_then_killed_during_the_revision(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = Server(data).start(LTAA_TEST_PAUSE=f"18:{PAUSE.node}:before")
    try:
        parent = paused_parent(first)
        with first.client() as c:
            created = post(c, f"/runs/{parent}/revisions", HEAVY_DOWN)
            # One transaction: the parent is superseded as the revision exists.
            parent_state = c.get(f"/runs/{parent}").json()
        assert created["revision_of"] == parent and created["revision"] == 1
        assert parent_state["status"] == "superseded"
        assert parent_state["superseded_by"] == created["id"]
        # The revision's first free task is 18: it holds there too. Kill it mid-run.
        wait_for_log(first, PAUSE.message(), count=2)
    finally:
        first.kill()

    second = Server(data).start()
    try:
        revision = second.wait_for(created["id"], finished)
        reference = uninterrupted_revision(second)
        with second.client() as c:
            parent_state = c.get(f"/runs/{parent}").json()
            parent_rows = jsonl_decisions(c, parent)
            revision_rows = jsonl_decisions(c, created["id"])
            verify = c.get(f"/runs/{created['id']}/trace/verify").json()
            parent_verify = c.get(f"/runs/{parent}/trace/verify").json()
            lineage = c.get(f"/runs/{parent}/revisions").json()
            trace = c.get(f"/runs/{created['id']}/trace").json()
            pins = [
                {"task_id": a["task_id"], "robot": a["robot"]} for a in revision["assignments"][:18]
            ]
            optimal = post(
                c,
                "/allocate",
                {
                    "scenario": "baseline",
                    "mode": "balanced",
                    "solver": "optimal",
                    "pinned": pins,
                    "unavailable": ["heavy"],
                },
            )
    finally:
        second.stop()

    # The parent: superseded for good, decision 18 never stored, its record still verifies.
    assert parent_state["status"] == "superseded"
    assert [d["task_index"] for d in parent_rows] == list(range(18))
    assert parent_verify["ok"] is True, parent_verify
    # Exactly one revision, and it plans as an uninterrupted revision does.
    assert [r["id"] for r in lineage] == [parent, created["id"]]
    assert revision["resumes"] == 1
    assert plan(revision) == plan(reference)
    # Its decisions 0-17 are the parent's, each naming the parent decision's chain hash.
    pinned = revision_rows[:18]
    assert [d["task_index"] for d in pinned] == list(range(18))
    for mine, theirs in zip(pinned, parent_rows, strict=True):
        assert mine["pinned"] is True and mine["pinned_from"] == theirs["chain_hash"]
        assert (mine["robot_name"], mine["expected_success"]) == (
            theirs["robot_name"],
            theirs["expected_success"],
        )
    assert all(d.get("pinned") is None for d in revision_rows[18:])
    assert all(a["robot"] != "heavy" for a in revision["assignments"][18:])
    # Guided: at the optimum given the pins and the fleet, with no regret.
    es = revision["metrics"]["expected_success"]
    assert abs(es - optimal["metrics"]["expected_success"]) < 1e-9
    assert abs(revision["regret"]) < 1e-9
    # The record: `revised` first, and verify checks the link to the parent.
    assert trace["events"][0]["kind"] == "revised"
    assert verify["ok"] is True, verify
    assert verify["parent"] == {"run_id": parent, "ok": True, "reason": verify["parent"]["reason"]}


def test_kill_right_after_the_202_leaves_exactly_one_revision(tmp_path: Path) -> None:
    data = tmp_path / "data"
    first = Server(data).start(LTAA_TEST_PAUSE=f"18:{PAUSE.node}:before")
    try:
        parent = paused_parent(first)
        with first.client() as c:
            created = post(c, f"/runs/{parent}/revisions", HEAVY_DOWN)
    finally:
        first.kill()
    second = Server(data).start()
    try:
        revision = second.wait_for(created["id"], finished)
        reference = uninterrupted_revision(second)
        with second.client() as c:
            lineage = c.get(f"/runs/{parent}/revisions").json()
            again = c.post(f"/runs/{parent}/revisions", json=HEAVY_DOWN)
            verify = c.get(f"/runs/{created['id']}/trace/verify").json()
    finally:
        second.stop()
    assert [r["id"] for r in lineage] == [parent, created["id"]]
    assert again.status_code == 409 and created["id"] in again.text
    assert plan(revision) == plan(reference)
    assert verify["ok"] is True, verify


def test_ltaa_revise_prints_the_diff(tmp_path: Path) -> None:
    from typer.testing import CliRunner

    from app.cli import cli

    server = Server(tmp_path / "data").start()
    try:
        with server.client() as c:
            parent = str(post(c, "/runs", GUIDED)["id"])
        server.wait_for(parent, finished)
        runner = CliRunner()
        args = ["revise", parent, "--robot-unavailable", "heavy", "--pin", "through:17"]
        result = runner.invoke(cli, [*args, "--url", server.url, "--reason", "hydraulics"])
        again = runner.invoke(cli, [*args, "--url", server.url])
        bad = runner.invoke(cli, ["revise", parent, "--pin", "through:x", "--url", server.url])
        with server.client() as c:
            lineage = c.get(f"/runs/{parent}/revisions").json()
    finally:
        server.stop()
    assert result.exit_code == 0, result.output
    assert "revision 1" in result.output and "heavy unavailable" in result.output
    assert "moved to another robot" in result.output and "expected success" in result.output
    assert len(lineage) == 2 and lineage[1]["status"] == "completed"
    assert again.exit_code == 1 and "409" in again.output and lineage[1]["id"] in again.output
    assert bad.exit_code == 1 and "--pin" in bad.output
