"""Server logs: one JSON object per line carrying run id and task index, or plain text."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from tests.api.conftest import ClientFactory
from tests.polling import wait_until


def _six_task_run(client: TestClient) -> str:
    baseline = next(s for s in client.get("/scenarios").json() if s["name"] == "baseline")
    run_id = str(
        client.post(
            "/runs", json={"tasks": baseline["tasks"][:6], "robots": baseline["robots"]}
        ).json()["id"]
    )
    wait_until(client, run_id, ("completed",), timeout=60)
    return run_id


def test_json_lines_carry_run_id_and_task_index(
    make_client: ClientFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    run_id = _six_task_run(make_client(log_format="json"))
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    records = [json.loads(line) for line in lines]  # every line is one JSON object
    assert all({"time", "level", "logger", "message"} <= set(r) for r in records)
    decisions = [r for r in records if r.get("run_id") == run_id and "task_index" in r]
    assert [r["task_index"] for r in decisions] == list(range(6))
    assert decisions[0]["message"].startswith("task 0 -> ")
    assert any(r["level"] == "WARNING" and "access control is off" in r["message"] for r in records)


def test_text_format_names_run_and_task(
    make_client: ClientFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    run_id = _six_task_run(make_client(log_format="text"))
    err = capsys.readouterr().err
    assert f"[run_id={run_id} task_index=5]" in err
    assert not err.lstrip().startswith("{")
