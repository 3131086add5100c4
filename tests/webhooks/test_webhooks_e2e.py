"""Webhooks through the real server (scripts/serve.sh, uvicorn subprocess) to a real
receiver on loopback: durable across SIGKILL, resumed after an outage."""

from __future__ import annotations

import random
import socket
import sqlite3
import time
from pathlib import Path
from typing import Any

import httpx
import pytest

from app.graph.pause import PausePoint
from tests.fakes.webhook_receiver import running_receiver
from tests.support.polling import eventually
from tests.support.server import Server, free_port

pytestmark = pytest.mark.e2e

RUN = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}
FAST = {
    "LTAA_WEBHOOK_ALLOW_PRIVATE": "true",
    "LTAA_WEBHOOK_POLL_S": "0.05",
    "LTAA_WEBHOOK_RETRY_DELAYS_S": ",".join(["0.2"] * 20),
}


def subscribe(server: Server, url: str, events: list[str] | None = None) -> dict[str, Any]:
    with server.client() as c:
        response = c.post("/webhooks", json={"url": url, "events": events or ["*"]})
    assert response.status_code == 201, response.text
    return dict(response.json())


def start_run(server: Server) -> str:
    with server.client() as c:
        response = c.post("/runs", json=RUN)
    assert response.status_code == 202, response.text
    return str(response.json()["id"])


def outbox(data_dir: Path) -> list[tuple[str, str, str, str]]:
    """(id, type, run id, state) of every delivery, read from the database file."""
    with sqlite3.connect(data_dir / "ltaa.db") as conn:
        return conn.execute(
            "SELECT id, event_type, run_id, state FROM webhook_deliveries ORDER BY created_at"
        ).fetchall()


def wait_all_delivered(data_dir: Path, timeout: float = 60) -> list[tuple[str, str, str, str]]:
    return eventually(
        lambda: outbox(data_dir),
        until=lambda rows: bool(rows) and all(r[3] == "delivered" for r in rows),
        what="every delivery in the outbox delivered",
        timeout=timeout,
        interval=0.1,
    )


def test_killed_after_completion_before_delivery_delivers_after_restart(tmp_path: Path) -> None:
    """The baseline acceptance, across a SIGKILL: the run completes with dispatch held (the
    test seam), the server is killed, and the restarted server delivers run.created and
    run.completed, signed, with the run's status and expected success."""
    data = tmp_path / "data"
    with running_receiver() as receiver:
        server = Server(data, env={**FAST, "LTAA_WEBHOOK_DISPATCH": "false"}).start()
        try:
            hook = subscribe(server, receiver.url)
            receiver.secret = hook["secret"]
            run_id = start_run(server)
            state = server.wait_for(run_id, lambda s: s["status"] == "completed")
            pending = outbox(data)
            assert {(t, s) for _, t, _, s in pending} == {
                ("run.created", "pending"),
                ("run.completed", "pending"),
            }
        finally:
            server.kill()
        assert receiver.snapshot() == []
        server = Server(data, env=FAST).start()
        try:
            receiver.wait_for(lambda got: len(got) >= 2, what="two requests")
            bodies = receiver.verified(hook["secret"])
            assert {r[0] for r in wait_all_delivered(data)} == receiver.ids()
        finally:
            server.stop()
    completed = next(b for b in bodies if b["type"] == "run.completed")["data"]
    assert completed["run_id"] == run_id and completed["status"] == "completed"
    assert completed["expected_success"] == pytest.approx(state["metrics"]["expected_success"])
    assert {b["type"] for b in bodies} == {"run.created", "run.completed"}


@pytest.mark.timeout(900)  # eleven server starts, beside the suite's other workers
def test_ten_kills_at_random_points_lose_no_webhook(tmp_path: Path) -> None:
    """Runs paused at a different task each start, a new run each time, and a SIGKILL at a
    random moment (recovering, dispatching, running): after the last restart the
    receiver's webhook-ids are exactly the outbox's (duplicates allowed, losses not)."""
    data = tmp_path / "data"
    rng = random.Random(14)
    with running_receiver(delay_s=0.03) as receiver:
        server = Server(data, env=FAST)
        try:
            server.start()
            hook = subscribe(server, receiver.url)
            receiver.secret = hook["secret"]
            runs = []
            for kill in range(10):
                if kill:
                    server.start(pause=PausePoint(3 * kill, "reason", after=False))
                runs.append(start_run(server))
                # A random moment, not a state to wait for: the kill lands wherever it lands.
                time.sleep(rng.uniform(0.0, 0.6))
                server.kill()
            server.start()
            for run_id in runs:
                server.wait_for(run_id, lambda s: s["status"] == "completed")
            rows = wait_all_delivered(data)
        finally:
            server.stop()
        received = receiver.ids()
        receiver.verified(hook["secret"])
    assert {r[0] for r in rows} == received
    types = {(run, t) for _, t, run, _ in rows}
    assert all((run, "run.created") in types and (run, "run.completed") in types for run in runs)
    assert any(t == "run.interrupted" for _, t, _, _ in rows)  # kills landed mid-run


def test_deliveries_resume_after_the_receiver_was_down_30_s(tmp_path: Path) -> None:
    data = tmp_path / "data"
    schedule = {**FAST, "LTAA_WEBHOOK_RETRY_DELAYS_S": "1,2,4,4,4,4,4,4,4,4,4,4"}
    server = Server(data, env=schedule).start()
    # The receiver's port, bound but not listening through the outage (a connection to it
    # is refused, as to a receiver that is down): no other test's socket can take it.
    held = socket.socket()
    held.bind(("127.0.0.1", free_port()))
    port = int(held.getsockname()[1])
    try:
        hook = subscribe(server, f"http://127.0.0.1:{port}/hooks")
        run_id = start_run(server)
        server.wait_for(run_id, lambda s: s["status"] == "completed")
        # The outage itself: nothing listens on the port for 30 s.
        time.sleep(30)
        with httpx.Client(base_url=server.url) as c:
            log = c.get(f"/webhooks/{hook['id']}/deliveries").json()
        assert len(log) == 2 and all(d["status"] == "pending" for d in log)
        assert all(d["attempts"] >= 4 for d in log)
        assert {a["outcome"] for d in log for a in d["attempt_log"]} == {"network_error"}
        held.close()
        with running_receiver(port=port) as receiver:
            receiver.secret = hook["secret"]
            receiver.wait_for(lambda got: len(got) >= 2, what="both deliveries", timeout=15)
            rows = wait_all_delivered(data, timeout=15)
            assert {r[0] for r in rows} == receiver.ids()
            receiver.verified(hook["secret"])
    finally:
        held.close()
        server.stop()
