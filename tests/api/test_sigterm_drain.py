"""SIGTERM drains the real server: running runs stop at a node boundary and are marked
interrupted, queued runs stay queued, the process exits by itself (even with a live-progress
watcher attached), and the next start resumes both to an uninterrupted run's result."""

from __future__ import annotations

import random
import signal
import sqlite3
import subprocess
import threading
from pathlib import Path
from typing import Any

import httpx
import pytest

from tests.support.polling import eventually
from tests.support.server import TRANSIENT_POLL_S, Server
from tests.support.sse import parse_events

pytestmark = pytest.mark.e2e

N_TASKS = 200
# Within this the server must have stopped its runs and exited by itself (the runs stop at
# their next node boundary: milliseconds with the rules reasoner).
DRAIN_LIMIT_S = 10


def instance(seed: int = 3) -> dict[str, Any]:
    rng = random.Random(seed)
    features = ["heavy", "dexterous", "careful"]
    robots = [
        {"name": f"r{i}", "success": {f: round(rng.uniform(0.3, 0.99), 2) for f in features}}
        for i in range(4)
    ]
    tasks = [
        {"id": t, "name": f"task {t}", "features": rng.sample(features, rng.randint(1, 2))}
        for t in range(N_TASKS)
    ]
    return {"tasks": tasks, "robots": robots, "mode": "balanced", "reasoner": "rules"}


def watch(url: str, seen: list[str]) -> None:
    """A supervisor's live view; the server ends it when it shuts down."""
    try:
        with httpx.stream("GET", url, timeout=httpx.Timeout(60)) as response:
            for event in parse_events(response.iter_lines()):
                seen.append(event.event)
    except httpx.HTTPError:
        pass  # cut off by the shutdown: a client reconnects with Last-Event-ID


def statuses(data: Path) -> dict[str, str]:
    with sqlite3.connect(data / "ltaa.db") as db:
        return dict(db.execute("SELECT id, status FROM runs").fetchall())


def assignments(state: dict[str, Any]) -> list[tuple[Any, str]]:
    return [(a["task_id"], a["robot"]) for a in state["assignments"]]


def finished(state: dict[str, Any]) -> bool:
    return state["status"] in ("completed", "failed", "cancelled")


def test_sigterm_interrupts_runs_at_a_node_boundary_and_the_next_start_resumes_them(
    tmp_path: Path,
) -> None:
    data = tmp_path / "data"
    body = instance()
    server = Server(data, env={"LTAA_MAX_CONCURRENT_RUNS": "1"}).start()
    with server.client() as c:
        running = c.post("/runs", json=body).json()["id"]
        queued = c.post("/runs", json=body).json()["id"]
    server.wait_for(running, lambda s: s["progress"]["allocated"] >= 20, interval=TRANSIENT_POLL_S)
    seen: list[str] = []
    watcher = threading.Thread(target=watch, args=(f"{server.url}/runs/{running}/events", seen))
    watcher.start()
    eventually(
        lambda: "decision" in seen, timeout=10, interval=0.05, what="a decision event streamed"
    )
    assert "decision" in seen  # the stream is live when the signal comes

    assert server.proc is not None
    server.proc.send_signal(signal.SIGTERM)
    try:
        code = server.proc.wait(timeout=DRAIN_LIMIT_S)
    except subprocess.TimeoutExpired:
        server.kill()
        pytest.fail(
            f"still running {DRAIN_LIMIT_S} s after SIGTERM:\n{server.log.read_text()[-3000:]}"
        )
    watcher.join(timeout=5)
    log = server.log.read_text()
    # uvicorn (>= 0.29) re-raises the signal it shut down for once it is done, so a clean
    # drain ends "terminated by SIGTERM" (143 in a shell), as process managers expect; a
    # failed drain would not log the application's shutdown as complete.
    assert code == -signal.SIGTERM, (code, log[-3000:])
    assert "Application shutdown complete." in log, log[-3000:]
    assert "Traceback" not in log, log[-3000:]
    assert not watcher.is_alive()
    # Stopped mid-run (an event stream no longer holds the shutdown until the run ends),
    # marked interrupted by the drain; the queued run never started.
    assert statuses(data) == {running: "interrupted", queued: "queued"}

    server = Server(data).start()
    try:
        resumed = server.wait_for(running, finished)
        second = server.wait_for(queued, finished)
        with server.client() as c:
            trace = c.get(f"/runs/{running}/trace").json()
            reference_id = c.post("/runs", json=body).json()["id"]
        reference = server.wait_for(reference_id, finished)
    finally:
        server.stop()

    assert resumed["status"] == second["status"] == reference["status"] == "completed"
    assert assignments(resumed) == assignments(second) == assignments(reference)
    assert (resumed["resumes"], second["resumes"]) == (1, 0)
    assert [d["task_index"] for d in trace["decisions"]] == list(range(N_TASKS))
    events = {e["kind"]: e["detail"] for e in trace["events"]}
    # One interrupted event, from the drain: none "found running at start-up".
    assert [e["kind"] for e in trace["events"]] == [
        "created",
        "started",
        "interrupted",
        "resumed",
        "completed",
    ], trace["events"]
    assert events["interrupted"] == {"reason": "server shutting down"}
    integrity = events["resumed"]["integrity"]
    assert integrity["ok"] is True
    assert 20 <= integrity["resume_at_task"] < N_TASKS
    # A drain stops between nodes, so the checkpoint never lags the decisions.
    assert integrity["checkpoint_task_index"] == integrity["decisions_stored"]
