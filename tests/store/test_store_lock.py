"""One process per embedded SQLite store: a second one refuses to start, touching nothing."""

from __future__ import annotations

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.graph.pause import PausePoint
from app.main import create_app
from app.store.lock import Holder, StoreInUseError, listen_url
from tests.support.polling import wait_logged, wait_until

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


def test_the_lock_file_names_the_holder_and_where_it_serves(settings: Settings) -> None:
    with (
        TestClient(create_app(settings.model_copy(update={"port": 9123}))),
        pytest.raises(StoreInUseError) as refused,
    ):
        TestClient(create_app(settings)).__enter__()
    assert refused.value.holder.url == "http://127.0.0.1:9123"
    assert "serving http://127.0.0.1:9123" in str(refused.value)
    # A lock file written before the address was recorded held the pid alone.
    assert Holder.parse("4242") == Holder(pid="4242", url=None)
    assert listen_url("0.0.0.0", 9000) == "http://127.0.0.1:9000"
    assert listen_url("::", 9000) == "http://[::1]:9000"
