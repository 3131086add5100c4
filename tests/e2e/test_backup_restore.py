"""Backup while a run executes, restore into a new data directory, resume there: the run
goes on from the backup's point and ends with the allocation of an uninterrupted run."""

from __future__ import annotations

import json
import os
import subprocess
import sys
import time
from pathlib import Path
from typing import Any

import pytest

from tests.e2e.server import ROOT, Server
from tests.e2e.test_durable_runs import _big_instance

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(1500)]

N_TASKS = 3_000


def _ltaa(data: Path, *args: str, port: int | None = None) -> subprocess.CompletedProcess[str]:
    env = {**os.environ, "LTAA_DATA_DIR": str(data)}
    if port is not None:
        env["LTAA_PORT"] = str(port)
    return subprocess.run(
        [sys.executable, "-c", "from app.cli import main; main()", *args],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )


def _wait(server: Server, run_id: str, predicate: Any, timeout: float = 900) -> dict[str, Any]:
    """Polls with a one-assignment page, twice a second: a full page of a 3,000-task run
    at 20 Hz would cost the server more CPU than the run it watches."""
    deadline = time.monotonic() + timeout
    with server.client() as c:
        while time.monotonic() < deadline:
            state: dict[str, Any] = c.get(f"/runs/{run_id}", params={"limit": 1}).json()
            if predicate(state):
                return state
            time.sleep(0.5)
    raise AssertionError(f"run {run_id} did not reach the state in {timeout:g} s: {state}")


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
        _wait(source, run_id, lambda s: s["progress"]["allocated"] >= N_TASKS * 4 // 10)
        taken = _ltaa(source.data_dir, "backup", str(tmp_path / "backup"), port=source.port)
        assert taken.returncode == 0, taken.stderr
        manifest = json.loads(taken.stdout)
        assert manifest["taken_by"] == "server"  # the server held the store
        at_backup = manifest["runs"][run_id]
        assert N_TASKS * 4 // 10 <= at_backup < N_TASKS
        # The original run goes on after the hold: it is the uninterrupted reference.
        done = _wait(source, run_id, lambda s: s["status"] == "completed")
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
        resumed = _wait(restored, run_id, lambda s: s["status"] == "completed")
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
    # store's lock file names the server's address, so the command asks that server.
    server = Server(tmp_path / "data").start(LTAA_BACKUP_DIR=str(tmp_path))
    try:
        with server.client() as c:
            run_id = str(c.post("/runs", json={"scenario": "baseline"}).json()["id"])
        _wait(server, run_id, lambda s: s["status"] == "completed")
        assert server.port != 8000
        taken = _ltaa(server.data_dir, "backup", str(tmp_path / "backup"))
        assert taken.returncode == 0, taken.stderr
        manifest = json.loads(taken.stdout)
        assert manifest["taken_by"] == "server", manifest
        assert manifest["dest"] == str((tmp_path / "backup").resolve()) and manifest["files"]
    finally:
        server.stop()
