"""An upgrade from the last landed release: a data directory that release wrote (its own
code, its own migrations, a real server) is served by this checkout, which migrates it on
start-up. Every run stays readable and verifiable, online and offline, and can be revised.

The release is a commit of this repository's history (`git archive`), so the test needs a
clone with history, as CI's is. Bump LANDED when a release lands with new migrations.
"""

from __future__ import annotations

import io
import subprocess
import tarfile
from pathlib import Path
from typing import Any

import pytest

from tests.support.offline_check import check_offline
from tests.support.server import ROOT, Server

pytestmark = [pytest.mark.e2e, pytest.mark.timeout(600)]

# The last landed release (migration head 0009: console sessions).
LANDED = "6d947459e78e3d00e4c0a4e713f01b6e957b9374"


def _release_tree(dest: Path) -> Path:
    archive = subprocess.run(
        [
            "git",
            "-C",
            str(ROOT),
            "archive",
            "--format=tar",
            LANDED,
            "app",
            "migrations",
            "alembic.ini",
            "scripts",
        ],
        capture_output=True,
        check=True,
        timeout=60,
    ).stdout
    with tarfile.open(fileobj=io.BytesIO(archive)) as tar:
        tar.extractall(dest, filter="data")
    return dest


def _completed(server: Server, run_id: str) -> dict[str, Any]:
    return server.wait_for(run_id, lambda s: s["status"] == "completed", timeout=180)


def _record(server: Server, run_id: str) -> dict[str, Any]:
    with server.client() as c:
        return {
            "run": c.get(f"/runs/{run_id}").json(),
            "verify": c.get(f"/runs/{run_id}/trace/verify").json(),
            "export": c.get(f"/runs/{run_id}/trace", params={"format": "jsonl"}).text,
        }


def _same_plan(before: dict[str, Any], after: dict[str, Any]) -> None:
    keys = ("task_index", "task_id", "robot", "success", "fallback")
    assert [{k: a[k] for k in keys} for a in after["assignments"]] == [
        {k: a[k] for k in keys} for a in before["assignments"]
    ]
    for field in ("status", "metrics", "revision_of", "revision", "superseded_by", "signoffs"):
        assert after[field] == before[field], field


def test_a_store_written_by_the_landed_release_upgrades_and_still_verifies(
    tmp_path: Path,
) -> None:
    data = tmp_path / "data"
    old = Server(data, root=_release_tree(tmp_path / "release")).start(timeout=120)
    try:
        with old.client() as c:
            parent = c.post("/runs", json={"scenario": "baseline", "reasoner": "rules"}).json()
            _completed(old, parent["id"])
            revision = c.post(
                f"/runs/{parent['id']}/revisions",
                json={
                    "changes": [{"type": "robot_unavailable", "robot": "heavy"}],
                    "pin": {"through_task_index": 9},
                    "reason": "heavy robot hydraulic fault",
                },
            ).json()
            _completed(old, revision["id"])
            reported = c.post(
                f"/runs/{revision['id']}/execution",
                json={"updates": [{"task_id": 0, "state": "started"}]},
            )
            assert reported.status_code == 200, reported.text
            signed = c.post(f"/runs/{parent['id']}/signoff", json={"statement": "read it all"})
            assert signed.status_code == 201, signed.text
            # The release's own code answered (its trace had no pinned_from yet).
            old_trace = c.get(f"/runs/{revision['id']}/trace").json()
            assert "pinned_from" not in old_trace["decisions"][0]
        before = {r: _record(old, r) for r in (parent["id"], revision["id"])}
    finally:
        old.stop()
    assert all(b["verify"]["ok"] for b in before.values())

    new = Server(data).start(timeout=120)  # this checkout: migrates the store, then serves
    try:
        for run_id, then in before.items():
            now = _record(new, run_id)
            _same_plan(then["run"], now["run"])
            assert now["verify"]["ok"] is True, now["verify"]
            assert now["verify"]["heads"] == then["verify"]["heads"]
            assert now["verify"]["signoffs_ok"] == then["verify"]["signoffs_ok"]
            export = tmp_path / f"{run_id}.jsonl"
            export.write_text(now["export"])
            offline = check_offline(export)
            assert offline.returncode == 0, offline.stdout + offline.stderr
        with new.client() as c:
            lineage = c.get(f"/runs/{revision['id']}/revisions").json()
            assert [r["id"] for r in lineage] == [parent["id"], revision["id"]]
            # The old record goes on: a revision of the old revision plans and completes.
            again = c.post(
                f"/runs/{revision['id']}/revisions",
                json={
                    "changes": [{"type": "robot_available", "robot": "heavy"}],
                    "reason": "fixed",
                },
            )
            assert again.status_code == 202, again.text
        third = _completed(new, again.json()["id"])
        assert third["revision"] == 2 and len(third["assignments"]) == 36
        with new.client() as c:
            assert c.get(f"/runs/{third['id']}/trace/verify").json()["ok"] is True
            trace = c.get(f"/runs/{revision['id']}/trace").json()
        # The old revision's trace reads with today's schema, its pins named.
        assert [d["task_index"] for d in trace["decisions"] if d["pinned"]] == list(range(10))
    finally:
        new.stop()
