"""Backup and restore without a server (the CLI copies directly) and the supervisor
endpoint's refusals."""

from __future__ import annotations

import sqlite3
import time
from pathlib import Path

from fastapi.testclient import TestClient
from typer.testing import CliRunner

from app.cli import cli
from app.config import Settings
from app.main import create_app


def _completed_store(client: TestClient) -> str:
    run_id = str(
        client.post("/runs", json={"scenario": "baseline", "reasoner": "rules"}).json()["id"]
    )
    for _ in range(600):
        if client.get(f"/runs/{run_id}").json()["status"] == "completed":
            return run_id
        time.sleep(0.05)
    raise AssertionError("run did not complete")


def test_the_endpoint_backs_up_and_refuses_a_used_destination(
    client: TestClient, settings: Settings, tmp_path: Path
) -> None:
    run_id = _completed_store(client)
    outside = client.post("/admin/backup", json={"dest": str(tmp_path / "b1")})
    assert outside.status_code == 422 and "LTAA_BACKUP_DIR" in outside.json()["detail"][0]["msg"]
    tmp_path = settings.data_dir / "backups"  # the default LTAA_BACKUP_DIR
    answer = client.post("/admin/backup", json={"dest": str(tmp_path / "b1")})
    assert answer.status_code == 200, answer.text
    body = answer.json()
    assert set(body["files"]) == {"ltaa.db", "checkpoints.sqlite"}
    assert (tmp_path / "b1" / "manifest.json").is_file()
    assert body["runs"] == {}  # the completed run is not one to resume
    with sqlite3.connect(tmp_path / "b1" / "ltaa.db") as conn:
        assert conn.execute("SELECT status FROM runs WHERE id = ?", (run_id,)).fetchone() == (
            "completed",
        )
    again = client.post("/admin/backup", json={"dest": str(tmp_path / "b1")})
    assert again.status_code == 409
    assert again.json()["detail"][0]["loc"] == ["body", "dest"]
    relative = client.post("/admin/backup", json={"dest": "relative/path"})
    assert relative.status_code == 422


def test_cli_backup_and_restore_without_a_server(settings: Settings, tmp_path: Path) -> None:
    with TestClient(create_app(settings)) as c:
        run_id = _completed_store(c)
    runner = CliRunner()
    env = {"LTAA_DATA_DIR": str(settings.data_dir)}
    taken = runner.invoke(cli, ["backup", str(tmp_path / "copy")], env=env)
    assert taken.exit_code == 0, taken.output
    assert '"taken_by": "direct"' in taken.stdout
    target = {"LTAA_DATA_DIR": str(tmp_path / "fresh")}
    put_back = runner.invoke(cli, ["restore", str(tmp_path / "copy")], env=target)
    assert put_back.exit_code == 0, put_back.output
    with sqlite3.connect(tmp_path / "fresh" / "ltaa.db") as conn:
        assert conn.execute(
            "SELECT count(*) FROM decisions WHERE run_id = ?", (run_id,)
        ).fetchone() == (36,)
    refused = runner.invoke(cli, ["restore", str(tmp_path / "copy")], env=target)
    assert refused.exit_code == 1 and "already holds a store" in refused.output
    not_backup = runner.invoke(
        cli, ["restore", str(tmp_path)], env={"LTAA_DATA_DIR": str(tmp_path / "x")}
    )
    assert not_backup.exit_code == 1 and "not an ltaa backup" in not_backup.output
