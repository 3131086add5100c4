"""Polling a run over an in-process TestClient until it reaches a status (test helper)."""

from __future__ import annotations

import time
from typing import Any

from fastapi.testclient import TestClient

FINISHED = ("completed", "failed", "cancelled", "interrupted")


def wait_until(
    client: TestClient, run_id: str, statuses: tuple[str, ...] = FINISHED, timeout: float = 90
) -> dict[str, Any]:
    """The run's state once its status is one of `statuses`; fails the test after `timeout`."""
    deadline = time.monotonic() + timeout
    while True:
        state: dict[str, Any] = client.get(f"/runs/{run_id}").json()
        if state["status"] in statuses:
            return state
        if time.monotonic() >= deadline:
            raise AssertionError(f"run {run_id} never reached {statuses}: {state}")
        time.sleep(0.02)
