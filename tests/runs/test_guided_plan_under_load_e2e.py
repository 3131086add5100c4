"""The plan a guided timed run follows does not depend on the machine's load
(docs/schedules.md#deterministic-search): the same guided run posted twice to the real
server, once with two CPU-bound processes running beside it, records the same
`guidance_planned` plan (with the deterministic budget it was solved on) and ends with
the same schedule. The burners stop by themselves (a bounded loop) and are killed when
the test ends."""

from __future__ import annotations

import subprocess
import sys
from pathlib import Path
from typing import Any

import pytest

from tests.support.server import Server

pytestmark = pytest.mark.e2e

BODY = {"scenario": "baseline_timed", "reasoner": "rules", "guidance": "optimizer"}
BURN_S = 120  # each burner stops by itself after this many seconds
BURNER = (
    f"import time\nend = time.monotonic() + {BURN_S}\nwhile time.monotonic() < end:\n    pass\n"
)


def _completed(state: dict[str, Any]) -> bool:
    assert state["status"] not in ("failed", "cancelled"), state
    return state["status"] == "completed"


def _guided_run(server: Server) -> tuple[dict[str, Any], list[tuple[str, str, float, float]]]:
    with server.client() as c:
        response = c.post("/runs", json=BODY)
        assert response.status_code == 202, response.text
        run_id = str(response.json()["id"])
    server.wait_for(run_id, _completed, timeout=300.0)
    with server.client() as c:
        trace = c.get(f"/runs/{run_id}/trace").json()
        schedule = c.get(f"/runs/{run_id}/schedule").json()
    (planned,) = [e["detail"] for e in trace["events"] if e["kind"] == "guidance_planned"]
    placed = sorted(
        (str(s["task_id"]), str(s["robot"]), float(s["start"]), float(s["end"]))
        for s in schedule["tasks"]
    )
    return planned, placed


def test_a_guided_plan_is_the_same_on_a_quiet_and_on_a_loaded_machine(tmp_path: Path) -> None:
    server = Server(tmp_path / "data").start()
    burners: list[subprocess.Popen[bytes]] = []
    try:
        quiet_plan, quiet_schedule = _guided_run(server)
        burners = [subprocess.Popen([sys.executable, "-c", BURNER]) for _ in range(2)]
        loaded_plan, loaded_schedule = _guided_run(server)
        assert all(b.poll() is None for b in burners), "the load ended before the run did"
    finally:
        for b in burners:
            b.kill()
            b.wait(timeout=10)
        server.stop()
    assert quiet_plan["robots"] and quiet_plan["robots"] == loaded_plan["robots"]
    assert quiet_plan["starts"] == loaded_plan["starts"]
    assert quiet_schedule == loaded_schedule
    budget = loaded_plan["budget"]
    assert budget["deterministic_budget"] > 0 and budget["workers"] == 1
    assert budget["wall_cut"] is False
    assert quiet_plan["budget"] == budget
