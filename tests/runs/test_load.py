"""Load on one real server with the SQLite default (benchmarks/load.py's round, asserted on
correctness only): 20 runs executing at once and 200 concurrent POST /allocate calls."""

from __future__ import annotations

from collections import defaultdict
from pathlib import Path

import pytest

from benchmarks.load import (
    LOCKED,
    N_ALLOCATE,
    N_RUNS,
    SCENARIOS,
    SERVER_ENV,
    SOLVERS,
    drive,
    failures,
)
from tests.support.server import Server

pytestmark = pytest.mark.e2e


def test_twenty_runs_and_200_allocate_calls_on_one_sqlite_server(tmp_path: Path) -> None:
    server = Server(tmp_path / "data", env=SERVER_ENV).start()
    try:
        result = drive(server.url)
        with server.client() as c:
            runs = c.get("/runs", params={"limit": 500}).json()
    finally:
        server.stop()
    log = server.log.read_text()

    assert failures(result, log) == []
    assert LOCKED not in log
    assert [c.status for c in result.calls] == [200] * N_ALLOCATE
    # Concurrent calls do not leak into each other: every solver gives one answer per
    # scenario, whatever else the server was doing at the time.
    answers: defaultdict[tuple[str, str], set[float | None]] = defaultdict(set)
    for call in result.calls:
        answers[(call.solver, call.scenario)].add(call.expected_success)
    assert set(answers) == {(s, sc) for s in SOLVERS for sc in SCENARIOS}
    assert all(len(values) == 1 and None not in values for values in answers.values()), answers

    assert result.create_statuses == [202] * N_RUNS
    assert len(runs) == N_RUNS and {r["status"] for r in runs} == {"completed"}
    assert [r["status"] for r in result.runs] == ["completed"] * N_RUNS
    # Nothing lost, nothing doubled, and the same deterministic allocation every time.
    allocations = {
        tuple((a["task_index"], a["robot"]) for a in r["assignments"]) for r in result.runs
    }
    assert len(allocations) == 1
    assert [t for t, _ in allocations.pop()] == list(range(36))
