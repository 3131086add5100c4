"""Safe upgrades against the real server: a run interrupted under one graph version is
refused (blocked, an upgrade_blocked event, an error naming both versions and the
choices) by a server of another version, and claimed by no worker; under the same
version, or back under its own, it resumes."""

from __future__ import annotations

import time
from pathlib import Path
from typing import Any

import pytest

from tests.support.server import Server

pytestmark = pytest.mark.e2e

BODY = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
OLD, NEW = "g1-oldoldoldold", "g1-newnewnewnew"


def _interrupted_run(data: Path, version: str) -> str:
    """A run killed at task 10 by a server claiming `version`."""
    first = Server(data).start(LTAA_TEST_PAUSE="10:reason:before", LTAA_TEST_GRAPH_VERSION=version)
    try:
        assert first.client().get("/health").json()["graph_version"] == version
        with first.client() as c:
            run_id = str(c.post("/runs", json=BODY).json()["id"])
        first.wait_for(run_id, lambda s: s["progress"]["allocated"] >= 10)
    finally:
        first.kill()
    return run_id


def _events(server: Server, run_id: str) -> list[dict[str, Any]]:
    with server.client() as c:
        return list(c.get(f"/runs/{run_id}/trace").json()["events"])


def test_a_run_interrupted_under_another_graph_version_is_blocked(tmp_path: Path) -> None:
    data = tmp_path / "data"
    run_id = _interrupted_run(data, OLD)

    upgraded = Server(data).start(LTAA_TEST_GRAPH_VERSION=NEW)
    try:
        state = upgraded.wait_for(run_id, lambda s: s["status"] != "interrupted")
        assert state["status"] == "blocked"
        assert state["graph_version"] == OLD
        assert state["progress"]["allocated"] == 10  # nothing ran under the new graph
        error = state["error"]
        assert OLD in error and NEW in error
        assert "finish it with a release" in error and "revise it" in error
        blocked = [e for e in _events(upgraded, run_id) if e["kind"] == "upgrade_blocked"]
        assert len(blocked) == 1
        assert blocked[0]["detail"]["started_under"] == OLD
        assert blocked[0]["detail"]["current"] == NEW
        # No worker claims it: it stays blocked, with one event, however long we look.
        time.sleep(1.0)
        with upgraded.client() as c:
            assert c.get(f"/runs/{run_id}").json()["status"] == "blocked"
            # A supervisor's resume under the wrong version blocks it again, once more.
            assert c.post(f"/runs/{run_id}/resume").status_code == 202
        again = upgraded.wait_for(run_id, lambda s: s["status"] == "blocked")
        assert again["progress"]["allocated"] == 10
        kinds = [e["kind"] for e in _events(upgraded, run_id)]
        assert kinds.count("upgrade_blocked") == 2
    finally:
        upgraded.kill()

    # Back under its own version: a supervisor resumes it and it completes.
    old = Server(data).start(LTAA_TEST_GRAPH_VERSION=OLD)
    try:
        with old.client() as c:
            assert c.get(f"/runs/{run_id}").json()["status"] == "blocked"  # not auto-resumed
            assert c.post(f"/runs/{run_id}/resume").status_code == 202
        done = old.wait_for(run_id, lambda s: s["status"] == "completed")
        assert done["progress"]["allocated"] == 36 and done["graph_version"] == OLD
    finally:
        old.stop()


def test_a_run_interrupted_under_the_same_graph_version_resumes(tmp_path: Path) -> None:
    data = tmp_path / "data"
    run_id = _interrupted_run(data, OLD)
    same = Server(data).start(LTAA_TEST_GRAPH_VERSION=OLD)
    try:
        done = same.wait_for(run_id, lambda s: s["status"] in ("completed", "blocked"))
        assert done["status"] == "completed" and done["resumes"] == 1
        assert "upgrade_blocked" not in [e["kind"] for e in _events(same, run_id)]
    finally:
        same.stop()
