"""The hash chain across crashes: SIGKILL the real server where a node has written its rows but
LangGraph has not checkpointed the step, so the node re-runs after restart and writes the same
rows again. The resumed run's trace must verify, with the links written before the crash."""

from __future__ import annotations

import sqlite3
from pathlib import Path

import pytest

from app.graph.pause import PausePoint
from tests.support.server import Server

pytestmark = pytest.mark.e2e

BODY = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}


def _stored_links(data: Path) -> dict[int, str]:
    with sqlite3.connect(data / "ltaa.db") as db:
        return dict(db.execute("SELECT task_index, chain_hash FROM decisions"))


def _written_at(data: Path, task_index: int) -> str:
    with sqlite3.connect(data / "ltaa.db") as db:
        return str(
            db.execute(
                "SELECT created_at FROM decisions WHERE task_index = ?", (task_index,)
            ).fetchone()[0]
        )


def test_a_run_killed_mid_write_resumes_with_a_valid_chain(tmp_path: Path) -> None:
    data = tmp_path / "data"
    # After store_and_route: decision 18 is stored, the step's checkpoint is not, so the
    # store node re-runs and upserts decision 18 again. After reason: task 25's attempt is
    # stored and its decision is not yet.
    points = [PausePoint(18, "store_and_route", after=True), PausePoint(25, "reason", True)]
    before_kill: list[dict[int, str]] = []
    server = Server(data)
    for n, point in enumerate(points):
        server.start(pause=point)
        if n == 0:
            with server.client() as c:
                run_id = c.post("/runs", json=BODY).json()["id"]
        server.wait_for_log(point.message())
        before_kill.append(_stored_links(data))
        if n == 0:
            first_write = _written_at(data, 18)
        server.kill()
        server = Server(data)

    server.start()
    try:
        state = server.wait_for(run_id, lambda s: s["status"] in ("completed", "failed"))
        with server.client() as c:
            report = c.get(f"/runs/{run_id}/trace/verify").json()
            kinds = [e["kind"] for e in c.get(f"/runs/{run_id}/trace").json()["events"]]
    finally:
        server.stop()

    assert state["status"] == "completed" and state["resumes"] == 2, state
    assert kinds.count("interrupted") == kinds.count("resumed") == 2
    assert report["ok"] is True, report
    assert (report["decisions"], report["unchained"]) == (36, 0)
    assert report["events"] == len(kinds)
    assert sorted(before_kill[0]) == list(range(19))  # decision 18 written before the kill
    assert _written_at(data, 18) != first_write  # ... and written again after the restart
    after = _stored_links(data)
    for links in before_kill:
        # Re-written rows kept their links, so nothing after them had to change either.
        assert {t: after[t] for t in links} == links
