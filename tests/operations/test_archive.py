"""Archive: old terminal lineages become verified JSON-lines files and tombstones (410
naming the file), runs not selected are untouched, and a kill -9 while archiving leaves
each run either archived-and-deleted or intact."""

from __future__ import annotations

import json
import os
import signal
import sqlite3
import subprocess
import sys
import time
from datetime import datetime
from pathlib import Path

import pytest
from fastapi.testclient import TestClient
from sqlalchemy import update

from app.config import Settings
from app.main import create_app
from app.operations.archive import archive
from app.store.db import make_engine, make_session_factory, transaction
from app.store.models import Run
from tests.support.offline_check import check_offline

ROOT = Path(__file__).resolve().parents[2]
LONG_AGO = "2020-06-01T00:00:00+00:00"
BEFORE = "2021-01-01T00:00:00+00:00"


def _completed(client: TestClient) -> str:
    body = {"scenario": "baseline", "reasoner": "rules"}
    run_id = str(client.post("/runs", json=body).json()["id"])
    for _ in range(600):
        if client.get(f"/runs/{run_id}").json()["status"] == "completed":
            return run_id
        time.sleep(0.05)
    raise AssertionError("run did not complete")


def _age(settings: Settings, *run_ids: str) -> None:
    with transaction(make_session_factory(make_engine(settings.db_url))) as session:
        session.execute(
            update(Run)
            .where(Run.id.in_(run_ids))
            .values(finished_at=datetime.fromisoformat(LONG_AGO))
        )


def test_old_runs_are_archived_verified_and_answer_410(
    client: TestClient, settings: Settings
) -> None:
    old, recent = _completed(client), _completed(client)
    _age(settings, old)
    answer = client.post("/admin/archive", json={"before": BEFORE})
    assert answer.status_code == 200, answer.text
    lineages = answer.json()["lineages"]
    assert [x["runs"] for x in lineages] == [[old]]
    archive_file = Path(lineages[0]["files"][0])
    assert archive_file.parent == settings.data_dir / "archive"

    gone = client.get(f"/runs/{old}")
    assert gone.status_code == 410
    assert archive_file.name in gone.json()["detail"][0]["msg"]
    assert client.get(f"/runs/{old}/trace/verify").status_code == 410
    # Every route that looks a run up says the same, at the place it named the run.
    for method, path, body in (
        ("GET", f"/runs/{old}/diff", None),
        ("GET", f"/runs/{old}/revisions", None),
        ("POST", f"/runs/{old}/revisions", {"changes": [], "reason": "late"}),
        ("POST", f"/runs/{old}/execution", {"updates": [{"task_id": 0, "state": "done"}]}),
    ):
        answer = client.request(method, path, json=body)
        assert answer.status_code == 410, (path, answer.text)
        detail = answer.json()["detail"][0]
        assert detail["loc"] == ["path", "run_id"] and archive_file.name in detail["msg"]
    assert client.get(f"/runs/{'0' * 32}/diff").status_code == 404  # never was: still 404
    replay = client.post("/runs", json={"reasoner": "replay", "replay_of": old})
    assert replay.status_code == 410 and replay.json()["detail"][0]["loc"] == ["body", "replay_of"]
    assert client.get(f"/runs/{recent}").json()["status"] == "completed"  # untouched
    assert client.get(f"/runs/{recent}/trace/verify").json()["ok"] is True

    lines = [json.loads(line) for line in archive_file.read_text().splitlines()]
    assert lines[-1]["type"] == "verify" and lines[-1]["ok"] is True
    checked = check_offline(archive_file)
    assert checked.returncode == 0, checked.stdout + checked.stderr
    with sqlite3.connect(settings.data_dir / "ltaa.db") as conn:
        assert conn.execute("SELECT count(*) FROM decisions WHERE run_id=?", (old,)).fetchone() == (
            0,
        )
        assert conn.execute(
            "SELECT count(*) FROM decisions WHERE run_id=?", (recent,)
        ).fetchone() == (36,)
    # Nothing older is left: a second archive does nothing.
    assert client.post("/admin/archive", json={"before": BEFORE}).json()["lineages"] == []


def test_a_kill_during_archiving_leaves_each_run_archived_or_intact(
    settings: Settings,
) -> None:
    with TestClient(create_app(settings)) as client:
        runs = [_completed(client) for _ in range(3)]
    _age(settings, *runs)
    env = {**os.environ, "LTAA_DATA_DIR": str(settings.data_dir)}
    killed = subprocess.run(
        [
            sys.executable,
            "-c",
            "from app.cli import main; main()",
            "archive",
            "--before",
            "2021-01-01",
        ],
        cwd=ROOT,
        env={**env, "LTAA_TEST_ARCHIVE_KILL_AFTER": "2"},
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert killed.returncode == -signal.SIGKILL, killed.stderr

    def state(run_id: str) -> tuple[bool, bool]:
        with sqlite3.connect(settings.data_dir / "ltaa.db") as conn:
            row = conn.execute("SELECT count(*) FROM runs WHERE id=?", (run_id,)).fetchone()[0]
            gone = conn.execute(
                "SELECT count(*) FROM archived_runs WHERE id=?", (run_id,)
            ).fetchone()[0]
            decisions = conn.execute(
                "SELECT count(*) FROM decisions WHERE run_id=?", (run_id,)
            ).fetchone()[0]
        assert (row, gone) in ((1, 0), (0, 1)), f"run {run_id}: row {row}, tombstone {gone}"
        assert decisions == (36 if row else 0)
        return bool(row), bool(gone)

    states = [state(r) for r in runs]
    assert states[0] == (False, True)  # archived before the kill
    assert (True, False) in states  # the run being archived at the kill is intact

    done = subprocess.run(
        [
            sys.executable,
            "-c",
            "from app.cli import main; main()",
            "archive",
            "--before",
            "2021-01-01",
        ],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert done.returncode == 0, done.stderr
    assert json.loads(done.stdout)["done_by"] == "direct"
    assert [state(r) for r in runs] == [(False, True)] * 3
    for run_id in runs:
        assert check_offline(settings.data_dir / "archive" / f"run-{run_id}.jsonl").returncode == 0


def test_a_run_signed_off_while_its_file_is_written_stays_unarchived(
    client: TestClient, settings: Settings
) -> None:
    """The archive writes a lineage's files, then deletes its rows: a sign-off that lands in
    between would be in neither. The lineage is left in place (and its file removed), to be
    archived whole next time."""
    run_id = _completed(client)
    _age(settings, run_id)
    dest = settings.data_dir / "archive-race"

    def sign_off_now(written: str) -> None:
        assert written == run_id
        signed = client.post(f"/runs/{run_id}/signoff", json={"statement": "checked late"})
        assert signed.status_code == 201, signed.text

    sessions = make_session_factory(make_engine(settings.db_url))
    done = archive(
        sessions=sessions,
        before=datetime.fromisoformat(BEFORE),
        dest=dest,
        after_file=sign_off_now,
    )
    assert done == []
    assert list(dest.iterdir()) == []
    state = client.get(f"/runs/{run_id}").json()
    assert state["status"] == "completed" and len(state["signoffs"]) == 1
    # Next time the lineage goes whole: its file has the sign-off.
    again = client.post("/admin/archive", json={"before": BEFORE}).json()["lineages"]
    assert [x["runs"] for x in again] == [[run_id]]
    lines = Path(again[0]["files"][0]).read_text().splitlines()
    assert any(json.loads(line)["type"] == "annotation" for line in lines)


@pytest.mark.parametrize(
    ("body", "loc", "type_"),
    [
        ({"before": "2021-01-01T00:00:00"}, ["body", "before"], "timezone_aware"),
        ({"before": "1609459200"}, ["body", "before"], "datetime_parsing"),
        ({"before": 1609459200}, ["body", "before"], "datetime_type"),
        ({"before": "0001-01-01T00:00:00+14:00"}, ["body", "before"], "datetime_out_of_range"),
        ({"before": BEFORE, "dry_run": True}, ["body", "dry_run"], "extra_forbidden"),
    ],
)
def test_archive_takes_an_offset_and_nothing_else_naming_the_field(
    client: TestClient, body: dict[str, object], loc: list[str], type_: str
) -> None:
    refused = client.post("/admin/archive", json=body)
    assert refused.status_code == 422, refused.text
    assert [(d["loc"], d["type"]) for d in refused.json()["detail"]] == [(loc, type_)]


def test_archive_before_with_an_offset_is_the_same_instant_in_utc(
    client: TestClient, settings: Settings
) -> None:
    old = _completed(client)
    _age(settings, old)  # finished 2020-06-01T00:00:00Z
    # 2020-06-01T03:00+05:00 is 2020-05-31T22:00Z: before the run finished, so not archived.
    early = client.post("/admin/archive", json={"before": "2020-06-01T03:00:00+05:00"})
    assert early.status_code == 200, early.text
    assert early.json()["lineages"] == []
    late = client.post("/admin/archive", json={"before": "2020-05-31T21:00:00-05:00"})
    assert [x["runs"] for x in late.json()["lineages"]] == [[old]]


def test_backup_forbids_extra_fields_too(client: TestClient) -> None:
    refused = client.post("/admin/backup", json={"dest": "/nowhere", "force": True})
    assert refused.status_code == 422, refused.text
    assert [d["loc"] for d in refused.json()["detail"]] == [["body", "force"]]
