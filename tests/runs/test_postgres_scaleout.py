"""Scale-out acceptance: two API processes on one PostgreSQL database share ten runs; one
process is SIGKILLed mid-run and the other resumes its runs once their leases expire.

Every run completes exactly once (36 decision rows, one `started` and one `completed`
event), the killed process's runs resume in the survivor through the integrity check,
and every allocation equals the embedded SQLite service's for the same request.
"""

from __future__ import annotations

import time
from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.graph.pause import PausePoint
from app.main import create_app
from tests.support.polling import eventually
from tests.support.postgres import fresh_database, query
from tests.support.server import Server

pytestmark = pytest.mark.e2e

PAUSE_AT = 12  # the first process holds its runs inside task 12's reasoning node
HELD = PausePoint(PAUSE_AT, "reason", after=False)
A_SLOTS = 5
LEASE_S = 3.0

REQUESTS: list[dict[str, Any]] = [
    {"scenario": "baseline", "mode": "balanced"},
    {"scenario": "baseline", "mode": "success_focused"},
    {"scenario": "baseline", "mode": "aggressive_balance"},
    {"scenario": "baseline", "mode": "balanced", "max_deviation": 2},
    {"scenario": "heavy_excels", "mode": "balanced"},
    {"scenario": "heavy_excels", "mode": "aggressive_balance"},
    {"scenario": "medium_excels", "mode": "balanced"},
    {"scenario": "medium_excels", "mode": "success_focused"},
    {"scenario": "light_excels", "mode": "balanced"},
    {"scenario": "light_excels", "mode": "aggressive_balance"},
]


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    with fresh_database("ltaa_scaleout") as url:
        yield url


def _assignments(state: dict[str, Any]) -> list[tuple[Any, str]]:
    return [(a["task_id"], a["robot"]) for a in state["assignments"]]


def _wait_completed(client: TestClient, run_id: str) -> dict[str, Any]:
    def completed(state: dict[str, Any]) -> bool:
        if state["status"] != "completed":
            assert state["status"] in ("queued", "running"), state
        return state["status"] == "completed"

    state: dict[str, Any] = eventually(
        lambda: client.get(f"/runs/{run_id}").json(),
        until=completed,
        timeout=120,
        interval=0.05,
        what=f"reference run {run_id} completed",
    )
    return state


def _sqlite_reference(data_dir: Path) -> list[list[tuple[Any, str]]]:
    """The same requests through the embedded default (SQLite tables and checkpointer)."""
    settings = Settings(data_dir=data_dir, anthropic_api_key=None, anthropic_base_url=None)
    results = []
    with TestClient(create_app(settings)) as client:
        ids = [
            client.post("/runs", json={**body, "reasoner": "rules"}).json()["id"]
            for body in REQUESTS
        ]
        for run_id in ids:
            state = _wait_completed(client, run_id)
            results.append(_assignments(state))
    return results


def _events(server: Server, run_id: str) -> list[dict[str, Any]]:
    with server.client() as c:
        trace = c.get(f"/runs/{run_id}/trace")
    assert trace.status_code == 200, trace.text
    events: list[dict[str, Any]] = trace.json()["events"]
    return events


def _one(events: list[dict[str, Any]], kind: str) -> dict[str, Any]:
    found = [e for e in events if e["kind"] == kind]
    assert len(found) == 1, [e["kind"] for e in events]
    return found[0]


@pytest.mark.timeout(900)
def test_two_processes_one_killed_mid_run(tmp_path: Path, postgres_url: str) -> None:
    reference = _sqlite_reference(tmp_path / "sqlite")
    env = {
        "LTAA_DATABASE_URL": postgres_url,
        "LTAA_LEASE_S": str(LEASE_S),
        "LTAA_CLAIM_POLL_S": "0.5",
    }
    a = Server(
        tmp_path / "a",
        env={
            **env,
            "LTAA_WORKER_NAME": "api-a",
            "LTAA_MAX_CONCURRENT_RUNS": str(A_SLOTS),
        },
    )
    b = Server(
        tmp_path / "b", env={**env, "LTAA_WORKER_NAME": "api-b", "LTAA_MAX_CONCURRENT_RUNS": "4"}
    )
    try:
        a.start(pause=HELD)
        with a.client() as c:
            created = [c.post("/runs", json={**body, "reasoner": "rules"}) for body in REQUESTS]
        assert all(r.status_code == 202 for r in created), [r.text for r in created]
        run_ids = [str(r.json()["id"]) for r in created]
        # A claimed one run per free slot as they arrived; the rest wait, queued, for B.
        held_by_a = run_ids[:A_SLOTS]
        owners = {
            run: owner for run, owner in query(postgres_url, "SELECT id, lease_owner FROM runs")
        }
        assert all(str(owners[r]).startswith("api-a:") for r in held_by_a), owners
        assert all(owners[r] is None for r in run_ids[A_SLOTS:]), owners

        b.start()
        for run_id in held_by_a:  # held at the pause: the kill lands mid-run
            state = a.wait_for(run_id, lambda s: s["progress"]["allocated"] >= PAUSE_AT)
            assert state["status"] == "running"
        a.wait_for_log(HELD.message(), count=A_SLOTS)  # each of A's runs held there
        with a.client() as c:
            assert all(
                c.get(f"/runs/{r}").json()["progress"]["allocated"] == PAUSE_AT for r in held_by_a
            )
        killed_at = time.monotonic()
        a.kill()

        finals = [
            b.wait_for(
                run_id,
                lambda s: s["status"] == "completed" or s["status"] in ("failed", "cancelled"),
                timeout=300,
            )
            for run_id in run_ids
        ]
        takeover_s = time.monotonic() - killed_at
        events = {run_id: _events(b, run_id) for run_id in run_ids}
    finally:
        a.kill()
        b.stop()

    assert [s["status"] for s in finals] == ["completed"] * len(REQUESTS)
    assert takeover_s >= LEASE_S  # nobody took A's runs before their leases expired

    # Exactly once: 36 decision rows per run, one per task index, no duplicates.
    rows = query(
        postgres_url,
        "SELECT run_id, count(*), count(DISTINCT task_index), "
        "min(task_index), max(task_index) FROM decisions GROUP BY run_id",
    )
    assert {r[0]: r[1:] for r in rows} == {run_id: (36, 36, 0, 35) for run_id in run_ids}
    leases = query(postgres_url, "SELECT count(*) FROM runs WHERE lease_owner IS NOT NULL")
    assert leases == [(0,)]  # every lease released at completion

    for run_id, state in zip(run_ids, finals, strict=True):
        run_events = events[run_id]
        started, completed = _one(run_events, "started"), _one(run_events, "completed")
        assert completed["detail"]["decisions"] == 36
        if run_id in held_by_a:
            assert started["detail"]["worker"].startswith("api-a:")
            interrupted, resumed = _one(run_events, "interrupted"), _one(run_events, "resumed")
            assert interrupted["detail"]["lease_owner"] == started["detail"]["worker"]
            assert resumed["detail"]["worker"].startswith("api-b:")
            integrity = resumed["detail"]["integrity"]
            assert integrity["ok"] is True, integrity
            assert integrity["resume_at_task"] == PAUSE_AT
            assert integrity["decisions_stored"] == PAUSE_AT
            assert state["resumes"] == 1
            kinds = [e["kind"] for e in run_events]
            assert (
                kinds.index("started")
                < kinds.index("interrupted")
                < kinds.index("resumed")
                < kinds.index("completed")
            )
        else:
            assert started["detail"]["worker"].startswith("api-b:")
            assert not [e for e in run_events if e["kind"] in ("interrupted", "resumed")]
            assert state["resumes"] == 0

    assert [_assignments(s) for s in finals] == reference
