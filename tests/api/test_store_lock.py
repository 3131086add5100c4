"""One process per embedded SQLite store: a second one refuses to start, touching nothing."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.graph.pause import PausePoint
from app.main import create_app
from app.store.lock import StoreInUseError
from tests.polling import wait_logged, wait_until

BASELINE = {"scenario": "baseline", "mode": "balanced"}
HOLD = "3:reason:before"


def test_a_second_server_on_the_same_store_refuses_to_start(
    settings: Settings, caplog: pytest.LogCaptureFixture
) -> None:
    paused = settings.model_copy(update={"test_pause": HOLD})
    with TestClient(create_app(paused)) as first:
        run_id = first.post("/runs", json=BASELINE).json()["id"]
        wait_until(first, run_id, ("running",))
        # Held at task 3 from here on: the run stays running whatever happens next.
        wait_logged(caplog, PausePoint.from_setting(HOLD).message())
        with pytest.raises(StoreInUseError, match="another LTAA process"):
            TestClient(create_app(settings)).__enter__()
        # The live run was not taken over: no "interrupted"/"resumed" written by the other.
        # (No wait needed: the second app refused while making its worker, before it could
        # recover anything, so none of it is left running to write later.)
        kinds = [e["kind"] for e in first.get(f"/runs/{run_id}/trace").json()["events"]]
        assert kinds == ["created", "started"]
        assert first.get(f"/runs/{run_id}").json()["status"] == "running"
    # Once the first has stopped, the store is free again.
    with TestClient(create_app(settings)) as second:
        assert wait_until(second, run_id, ("completed",))["resumes"] == 1
