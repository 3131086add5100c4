"""Live progress against the real server: GET /runs/{id}/events over HTTP with httpx."""

from __future__ import annotations

import subprocess
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.support.server import BIN, ROOT, Server, free_port
from tests.support.sse import Event, parse_events

pytestmark = pytest.mark.e2e

SUPERVISOR_KEY = "e2e-supervisor-key-5Wq8Ns2Lr7"
CLIENT_KEY = "e2e-client-key-3Hx9Tb6Kv1Pd"
KEYS = f"{SUPERVISOR_KEY}:supervisor,{CLIENT_KEY}:client"
AS_SUPERVISOR = {"Authorization": f"Bearer {SUPERVISOR_KEY}"}
BASELINE = {"scenario": "baseline", "mode": "balanced", "reasoner": "rules"}


def _create(server: Server) -> str:
    with server.client() as c:
        created = c.post("/runs", json=BASELINE, headers={"X-API-Key": CLIENT_KEY})
    assert created.status_code == 202, created.text
    return str(created.json()["id"])


def _watch(server: Server, run_id: str, stop_after_decisions: int | None = None) -> list[Event]:
    events: list[Event] = []
    with httpx.stream(
        "GET",
        f"{server.url}/runs/{run_id}/events",
        headers=AS_SUPERVISOR,
        timeout=httpx.Timeout(30),
    ) as response:
        assert response.status_code == 200
        for event in parse_events(response.iter_lines()):
            events.append(event)
            decided = sum(1 for e in events if e.event == "decision")
            if stop_after_decisions is not None and decided >= stop_after_decisions:
                break  # leaving the block drops the connection mid-stream
    return events


def _wait_finished(server: Server, run_id: str) -> dict[str, Any]:
    return server.wait_for(
        run_id,
        lambda state: state["status"] not in ("queued", "running"),
        timeout=60,
        headers=AS_SUPERVISOR,
    )


def test_sse_delivers_all_36_decisions_in_order(tmp_path: Path) -> None:
    server = Server(tmp_path / "data", env={"LTAA_API_KEYS": KEYS}).start()
    try:
        with server.client() as c:
            assert c.get(f"/runs/{'0' * 32}/events").status_code == 401
        run_id = _create(server)
        events = _watch(server, run_id)

        # A watcher that hangs up after three decisions leaves the next run untouched.
        abandoned = _create(server)
        assert len([e for e in _watch(server, abandoned, 3) if e.event == "decision"]) == 3
        finished = _wait_finished(server, abandoned)
    finally:
        server.stop()

    decisions = [e.data for e in events if e.event == "decision"]
    assert [d["task_index"] for d in decisions] == list(range(36))
    assert [e.data["kind"] for e in events if e.event == "run"] == [
        "created",
        "started",
        "completed",
    ]
    # The run's last event, then the status the stream ends on.
    assert [(e.event, e.data.get("kind", e.data.get("status"))) for e in events[-2:]] == [
        ("run", "completed"),
        ("status", "completed"),
    ]
    assert events[-1].data["finished"] is True
    assert finished["status"] == "completed" and finished["progress"]["allocated"] == 36
    log = server.log.read_text()
    assert "Traceback" not in log and SUPERVISOR_KEY not in log and CLIENT_KEY not in log


def test_serve_refuses_a_public_address_without_keys(tmp_path: Path) -> None:
    env = {
        **Server(tmp_path / "data").env,
        "LTAA_BIN": f"{BIN}/",
        "HOST": "0.0.0.0",
        "PORT": str(free_port()),
    }
    env.pop("LTAA_API_KEYS", None)
    proc = subprocess.run(
        ["sh", str(ROOT / "scripts" / "serve.sh")],
        cwd=ROOT,
        env=env,
        capture_output=True,
        text=True,
        timeout=60,
    )
    assert proc.returncode != 0
    assert "refusing to start" in proc.stderr and "LTAA_API_KEYS" in proc.stderr
