"""Backup while a run executes, restore into a new data directory, resume there: the run
goes on from the backup's point and ends with the allocation of an uninterrupted run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.runs.test_durable_runs import _big_instance
from tests.support.server import ROOT, TRANSIENT_POLL_S, Server

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(900)]

# Large enough that the run is still executing when the backup lands (600 tasks to go): the
# hold stops it at a node boundary for the copy, without which the two files would
# disagree. The backup is asked for over HTTP the moment the run passes 40 %; `ltaa backup`
# makes the same call (the next test), but its process start (about 1.3 s of CPU) let the
# run go on by hundreds of tasks first, which took a 3,000-task run to stay mid-run.
N_TASKS = 1_000
AT_LEAST = N_TASKS * 4 // 10


def _ltaa(data: Path, *args: str) -> subprocess.CompletedProcess[str]:
    return subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", *args],
        cwd=ROOT,
        env={**os.environ, "LTAA_DATA_DIR": str(data)},
        capture_output=True,
        text=True,
        timeout=300,
    )


def _completed(state: dict[str, Any]) -> bool:
    return state["status"] == "completed"


def _assignments(server: Server, run_id: str) -> list[tuple[Any, str]]:
    with server.client() as c:
        state = c.get(f"/runs/{run_id}", params={"limit": N_TASKS}).json()
    return [(a["task_id"], a["robot"]) for a in state["assignments"]]


def test_backup_mid_run_restores_and_resumes_to_the_same_allocation(tmp_path: Path) -> None:
    body = _big_instance(N_TASKS, seed=3)
    source = Server(tmp_path / "data").start(LTAA_BACKUP_DIR=str(tmp_path))
    try:
        with source.client() as c:
            run_id = str(c.post("/runs", json=body).json()["id"])
            # Progress is polled with a one-assignment page; the run is read whole once.
            source.wait_for(
                run_id,
                lambda s: s["progress"]["allocated"] >= AT_LEAST,
                page=1,
                interval=TRANSIENT_POLL_S,
            )
            taken = c.post("/admin/backup", json={"dest": str(tmp_path / "backup")})
        assert taken.status_code == 200, taken.text
        at_backup = taken.json()["runs"][run_id]
        assert AT_LEAST <= at_backup < N_TASKS
        # The original run goes on after the hold: it is the uninterrupted reference.
        done = source.wait_for(run_id, _completed, timeout=600, page=1)
        assert done["resumes"] == 0
        reference = _assignments(source, run_id)
    finally:
        source.stop()

    restored_dir = tmp_path / "restored"
    put_back = _ltaa(restored_dir, "restore", str(tmp_path / "backup"))
    assert put_back.returncode == 0, put_back.stderr
    # Restore never overwrites a store.
    again = _ltaa(restored_dir, "restore", str(tmp_path / "backup"))
    assert again.returncode == 1 and "already holds a store" in again.stderr

    restored = Server(restored_dir).start()
    try:
        resumed = restored.wait_for(run_id, _completed, timeout=600, page=1)
        with restored.client() as c:
            events = c.get(f"/runs/{run_id}/trace", params={"limit": 1}).json()["events"]
        assert resumed["resumes"] == 1
        integrity = next(e for e in events if e["kind"] == "resumed")["detail"]["integrity"]
        assert integrity["ok"] is True
        # From the backup's point: its stored decisions, not the source's final count.
        assert integrity["decisions_stored"] == at_backup
        assert _assignments(restored, run_id) == reference
    finally:
        restored.stop()


def test_backup_finds_the_server_holding_the_store_wherever_it_listens(tmp_path: Path) -> None:
    # `make run PORT=9000`, then `ltaa backup DEST` in another shell with no LTAA_PORT: the
    # store's lock file names the server's address, so the command asks that server (the
    # POST /admin/backup the mid-run test above makes itself).
    server = Server(tmp_path / "data").start(LTAA_BACKUP_DIR=str(tmp_path))
    try:
        with server.client() as c:
            run_id = str(c.post("/runs", json={"scenario": "baseline"}).json()["id"])
        server.wait_for(run_id, _completed)
        assert server.port != 8000
        taken = _ltaa(server.data_dir, "backup", str(tmp_path / "backup"))
        assert taken.returncode == 0, taken.stderr
        manifest = json.loads(taken.stdout)
        assert manifest["taken_by"] == "server", manifest
        assert manifest["dest"] == str((tmp_path / "backup").resolve()) and manifest["files"]
    finally:
        server.stop()
