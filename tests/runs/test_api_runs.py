"""The /runs endpoints in-process: create, poll, trace, resume, cancel, and bad input."""

from __future__ import annotations

import sqlite3
from typing import Any

import pytest
from fastapi.testclient import TestClient
from sqlalchemy.engine import make_url

from app.config import Settings
from app.main import create_app
from tests.support.clients import ClientFactory
from tests.support.polling import eventually, wait_until

BASELINE = {"scenario": "baseline", "mode": "balanced"}


def _wait_allocated(client: TestClient, run_id: str, tasks: int) -> None:
    eventually(
        lambda: client.get(f"/runs/{run_id}").json()["progress"]["allocated"],
        until=lambda allocated: allocated >= tasks,
        timeout=30,
        what=f"run {run_id} allocated {tasks} tasks",
    )


def test_a_rules_run_completes_with_metrics_and_a_full_trace(client: TestClient) -> None:
    created = client.post("/runs", json=BASELINE)
    assert created.status_code == 202
    run_id = created.json()["id"]
    assert created.headers["location"] == f"/runs/{run_id}"

    state = wait_until(client, run_id, ("completed", "failed"))
    assert state["status"] == "completed", state
    assert state["progress"] == {"allocated": 36, "total": 36, "phase": "late"}
    assert sum(state["workload"].values()) == 36
    assert all(8 <= load <= 16 for load in state["workload"].values())
    assert len(state["assignments"]) == 36
    assert state["metrics"]["workload"] == state["workload"]
    assert state["usage"] == {"llm_calls": 0, "input_tokens": 0, "output_tokens": 0}
    assert state["resumes"] == 0

    trace = client.get(f"/runs/{run_id}/trace").json()
    assert [d["task_index"] for d in trace["decisions"]] == list(range(36))
    kinds = [e["kind"] for e in trace["events"]]
    assert kinds == ["created", "started", "completed"]
    first = trace["decisions"][0]
    assert first["phase"] == "early" and first["loads_before"] == [0, 0, 0]
    attempt = first["attempts"][0]
    assert attempt["accepted"] is True and attempt["quality"] >= 0.9
    assert set(attempt["scores"]) == {
        "explanation",
        "success_accuracy",
        "tradeoff_analysis",
        "workload_awareness",
        "mode_compliance",
        "phase_consistency",
        "logical_consistency",
        "confidence_justification",
    }
    assert attempt["user_prompt"] is None and attempt["reply"] is None

    with_prompts = client.get(f"/runs/{run_id}/trace", params={"include": "prompts"}).json()
    attempt = with_prompts["decisions"][0]["attempts"][0]
    assert "Stop" in attempt["user_prompt"] and "**Decision**" in attempt["reply"]

    assert client.get("/runs", params={"status": "completed"}).json()[0]["id"] == run_id
    assert client.get("/runs", params={"status": "failed"}).json() == []


def test_optimizer_guided_run_has_zero_regret_and_unguided_shows_its_gap(
    client: TestClient,
) -> None:
    guided = client.post(
        "/runs", json={**BASELINE, "mode": "aggressive_balance", "guidance": "optimizer"}
    ).json()["id"]
    plain = client.post("/runs", json={**BASELINE, "mode": "aggressive_balance"}).json()["id"]
    g = wait_until(client, guided, ("completed",))
    p = wait_until(client, plain, ("completed",))
    assert g["regret"] == pytest.approx(0.0, abs=1e-9)
    assert g["metrics"]["expected_success"] == pytest.approx(0.769444, abs=1e-6)
    gap = g["metrics"]["expected_success"] - p["metrics"]["expected_success"]
    assert p["regret"] == pytest.approx(gap, abs=1e-9) and gap > 0.01
    trace = client.get(f"/runs/{plain}/trace").json()
    assert sum(d["regret"] for d in trace["decisions"]) == pytest.approx(gap, abs=1e-9)
    prompt = client.get(f"/runs/{guided}/trace", params={"include": "prompts"}).json()
    assert "Optimizer guidance:" in prompt["decisions"][0]["attempts"][0]["user_prompt"]


def test_resuming_a_completed_run_is_a_conflict(client: TestClient) -> None:
    run_id = client.post("/runs", json=BASELINE).json()["id"]
    wait_until(client, run_id, ("completed",))
    for action in ("resume", "cancel"):
        response = client.post(f"/runs/{run_id}/{action}")
        assert response.status_code == 409
        assert response.json()["detail"][0]["loc"] == ["path", "run_id"]


def test_cancel_stops_a_running_run(make_client: ClientFactory) -> None:
    client = make_client(test_pause="5:reason:before")
    run_id = client.post("/runs", json=BASELINE).json()["id"]
    _wait_allocated(client, run_id, 5)
    assert client.post(f"/runs/{run_id}/cancel").status_code == 200
    state = wait_until(client, run_id, ("cancelled",))
    assert state["progress"]["allocated"] == 5
    trace = client.get(f"/runs/{run_id}/trace").json()
    assert trace["events"][-1]["kind"] == "cancelled"


def test_an_illegal_move_through_the_api_stays_a_409(make_client: ClientFactory) -> None:
    # The lifecycle table refuses cancelled -> running; the API says so before trying.
    client = make_client(test_pause="2:reason:before")
    run_id = client.post("/runs", json=BASELINE).json()["id"]
    _wait_allocated(client, run_id, 2)
    assert client.post(f"/runs/{run_id}/cancel").status_code == 200
    wait_until(client, run_id, ("cancelled",))
    for action in ("resume", "cancel"):
        response = client.post(f"/runs/{run_id}/{action}")
        assert response.status_code == 409, response.text
        assert "is cancelled" in response.json()["detail"][0]["msg"]


@pytest.mark.parametrize("path", ["/runs/nope", "/runs/nope/trace"])
def test_unknown_run_is_404_naming_the_id(client: TestClient, path: str) -> None:
    response = client.get(path)
    assert response.status_code == 404
    assert response.json()["detail"][0]["loc"] == ["path", "run_id"]


@pytest.mark.parametrize("action", ["resume", "cancel"])
def test_commands_on_an_unknown_run_are_404(client: TestClient, action: str) -> None:
    assert client.post(f"/runs/nope/{action}").status_code == 404


@pytest.mark.parametrize(
    ("body", "field"),
    [
        ({**BASELINE, "reasoner": "oracle"}, "reasoner"),
        ({**BASELINE, "reasoner": "anthropic"}, "reasoner"),
        ({**BASELINE, "mode": "fastest"}, "mode"),
        ({"scenario": "moon_base"}, "scenario"),
        (
            {
                "tasks": [{"id": i, "features": ["heavy"]} for i in range(4)],
                "robots": [{"name": n, "success": {"heavy": 0.5}} for n in "abc"],
                "max_deviation": 0,
            },
            "max_deviation",
        ),
        ({**BASELINE, "quality_threshold": 1.5}, "quality_threshold"),
        ({**BASELINE, "max_retries": -1}, "max_retries"),
        ({**BASELINE, "temperature": "hot"}, "temperature"),
        ({**BASELINE, "guidance": "oracle"}, "guidance"),
        ({**BASELINE, "surprise": 1}, "surprise"),
    ],
)
def test_bad_run_requests_are_4xx_and_write_nothing(
    client: TestClient, body: dict[str, Any], field: str
) -> None:
    response = client.post("/runs", json=body)
    assert 400 <= response.status_code < 500, response.text
    detail = response.json()["detail"]
    assert any(field in item["loc"] or field in item["msg"] for item in detail), detail
    assert client.get("/runs").json() == []


def test_status_filter_must_be_a_known_status(client: TestClient) -> None:
    response = client.get("/runs", params={"status": "sleeping"})
    assert response.status_code == 422
    assert response.json()["detail"][0]["loc"] == ["query", "status"]


def test_a_run_whose_record_fails_the_integrity_check_is_not_resumed(settings: Settings) -> None:
    paused = settings.model_copy(update={"test_pause": f"{5}:reason:before"})
    with TestClient(create_app(paused)) as first:
        run_id = first.post("/runs", json=BASELINE).json()["id"]
        _wait_allocated(first, run_id, 5)
    # Shut down mid-run (interrupted at task 5), then lose a stored decision.
    database = sqlite3.connect(make_url(settings.db_url).database or "")
    with database:
        database.execute("DELETE FROM decisions WHERE run_id = ? AND task_index = 2", (run_id,))
    database.close()

    with TestClient(create_app(settings)) as second:  # auto-resume at start-up
        state = wait_until(second, run_id, ("failed", "completed"))
        assert state["status"] == "failed"
        assert "integrity check failed" in state["error"]
        assert state["progress"]["allocated"] == 4  # nothing built on the broken record
        assert state["resumes"] == 0
        events = second.get(f"/runs/{run_id}/trace").json()["events"]
        assert events[-1]["kind"] == "integrity_failed"
        assert not events[-1]["detail"]["integrity"]["ok"]


def _checkpoints_of(settings: Settings, run_id: str) -> int:
    saver = sqlite3.connect(settings.checkpoint_file)
    try:
        return saver.execute(
            "SELECT count(*) FROM checkpoints WHERE thread_id = ?", (run_id,)
        ).fetchone()[0]
    finally:
        saver.close()


def test_checkpoints_go_when_a_run_can_no_longer_resume(settings: Settings) -> None:
    paused = settings.model_copy(update={"test_pause": f"{3}:reason:before"})
    with TestClient(create_app(paused)) as client:
        held = client.post("/runs", json=BASELINE).json()["id"]
        wait_until(client, held, ("running",))
        _wait_allocated(client, held, 3)
    # Shut down while the run waited at task 3: interrupted, its checkpoints kept.
    assert _checkpoints_of(settings, held) > 0
    with TestClient(create_app(settings)) as client:
        assert wait_until(client, held, ("completed",))["resumes"] == 1
        done = client.post("/runs", json=BASELINE).json()["id"]
        wait_until(client, done, ("completed",))
    # Completed: the record is in the app tables, the checkpoints are gone.
    assert _checkpoints_of(settings, held) == 0
    assert _checkpoints_of(settings, done) == 0
