"""Server logs: one JSON object per line carrying run id and task index, or plain text."""

from __future__ import annotations

import json

import pytest
from fastapi.testclient import TestClient

from tests.fakes.llm_providers import PROVIDERS
from tests.support.clients import ClientFactory
from tests.support.polling import wait_until


def _six_task_run(client: TestClient, **fields: str) -> str:
    baseline = next(s for s in client.get("/scenarios").json() if s["name"] == "baseline")
    run_id = str(
        client.post(
            "/runs", json={"tasks": baseline["tasks"][:6], "robots": baseline["robots"], **fields}
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


def test_llm_calls_leave_no_line_per_request_from_the_sdk_http_client(
    make_client: ClientFactory, capsys: pytest.CaptureFixture[str]
) -> None:
    """httpx logs every request URL at INFO: a line per LLM call in the server's log."""
    openai = PROVIDERS["openai"]
    with openai.fake() as api:
        client = make_client(log_format="json", **openai.settings(api))
        run_id = _six_task_run(client, reasoner="openai")
    assert len(api.requests) == 6  # the calls were made, through the SDK's httpx client
    records = [json.loads(line) for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert any(r.get("run_id") == run_id for r in records)  # the server's own lines remain
    # The SDK's client is httpx2 (httpx's successor); the webhook sender's is httpx.
    from_sdk = [r for r in records if r["logger"].split(".")[0] in ("httpx", "httpx2", "openai")]
    assert [r for r in from_sdk if r["level"] in ("DEBUG", "INFO")] == []
    host = api.base_url.split("//")[1].split("/")[0]
    assert not [r for r in records if host in r["message"]]
