"""Scale-out (docs/living-plans.md#revisions): two API processes on one PostgreSQL database. A run
held by one is revised through the other: the holder stops (fenced by the run's state, told by its
lease heartbeat), and the revision is executed exactly once."""

from __future__ import annotations

from collections.abc import Iterator
from pathlib import Path
from typing import Any

import pytest

from tests.plans.test_revisions_e2e import HEAVY_DOWN, PAUSE, finished, post, wait_for_log
from tests.support.postgres import fresh_database
from tests.support.server import Server

pytestmark = pytest.mark.e2e


@pytest.fixture(scope="module")
def postgres_url() -> Iterator[str]:
    with fresh_database("ltaa_revisions") as url:
        yield url


def test_a_revision_made_on_one_process_runs_exactly_once(
    tmp_path: Path, postgres_url: str
) -> None:
    env = {"LTAA_DATABASE_URL": postgres_url, "LTAA_LEASE_S": "3", "LTAA_CLAIM_POLL_S": "0.5"}
    a = Server(
        tmp_path / "a",
        env={
            **env,
            "LTAA_WORKER_NAME": "api-a",
            "LTAA_MAX_CONCURRENT_RUNS": "1",
            "LTAA_TEST_PAUSE": f"18:{PAUSE.node}:before",
        },
    )
    b = Server(tmp_path / "b", env={**env, "LTAA_WORKER_NAME": "api-b"})
    try:
        a.start()
        b.start()
        with a.client() as c:
            parent = str(post(c, "/runs", {"scenario": "baseline", "reasoner": "rules"})["id"])
        wait_for_log(a, PAUSE.message())
        with b.client() as c:
            created = post(c, f"/runs/{parent}/revisions", HEAVY_DOWN)
        revision = b.wait_for(created["id"], finished)
        # The holder lets go of the superseded parent within a heartbeat or two.
        a.wait_for(parent, lambda s: s["status"] == "superseded")
        with b.client() as c:
            events: list[dict[str, Any]] = c.get(f"/runs/{created['id']}/trace").json()["events"]
            parent_trace = c.get(f"/runs/{parent}/trace").json()
            verify = c.get(f"/runs/{created['id']}/trace/verify").json()
        wait_for_log(a, f"run {parent} stopped: superseded", timeout=20)
    finally:
        a.kill()
        b.stop()
    kinds = [e["kind"] for e in events]
    assert kinds.count("started") == 1 and kinds.count("completed") == 1
    assert "resumed" not in kinds and kinds[0] == "revised"
    assert [d["task_index"] for d in parent_trace["decisions"]] == list(range(18))
    parent_kinds = [e["kind"] for e in parent_trace["events"]]
    assert parent_kinds[-1] == "superseded" and "cancelled" not in parent_kinds
    assert len(revision["assignments"]) == 36 and verify["ok"] is True, verify
