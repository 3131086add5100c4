"""The timed-schedules benchmark's helpers on tiny inputs (not the bench itself)."""

from __future__ import annotations

from pathlib import Path

import pytest
from fastapi.testclient import TestClient

from app.config import Settings
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.main import create_app
from benchmarks import report
from benchmarks.timed_instances import construction_site
from benchmarks.timed_plots import makespan_figure
from benchmarks.timed_schedules import CpSatRow, MethodRow, allocate_body, body


def test_the_allocate_body_carries_every_time_field(tmp_path: Path) -> None:
    problem = Problem.build(construction_site(8, 2, seed=1), Mode.BALANCED)
    with TestClient(create_app(Settings(data_dir=tmp_path, anthropic_api_key=None))) as client:
        response = client.post("/allocate", json=allocate_body(problem, 2.0))
    assert response.status_code == 200, response.text
    tasks = response.json()["schedule"]["tasks"]
    # The server's instance is the same site: each task's length is its duration there.
    tm = problem.instance.timing
    names = [r.name for r in problem.instance.robots]
    for i, slot in enumerate(tasks):
        assert slot["end"] - slot["start"] == pytest.approx(
            tm.duration(i, names.index(slot["robot"]))
        )


def test_regrets_are_against_cp_sat_and_its_bound(tmp_path: Path) -> None:
    cp = CpSatRow("site", "feasible", 100.0, 80.0, 0.2, 1.0, 1.5, 3.0, 10.0, "m", 0.8, None)
    worse = MethodRow("site", "greedy", 0.75, 120.0, 0, 0.01)
    image = makespan_figure(
        ["site"], {"site": (100.0, 80.0)}, {("site", "greedy"): 120.0}, "t.png", tmp_path
    )
    text = body([cp], [(cp, worse)], {0.5: (0.4, "answer: feasible")}, image)
    assert "| site | 10 s | feasible | 100 | - | 80 | 20.0% |" in text
    assert (
        "- `/allocate` with `schedule` on 36 tasks under 1 s: 0.40 s at the shorter limit (met)"
        in text
    )
    assert "not proven, 1.5 s CPU at load 3.0 (**missed**)" in text
    assert "| site | greedy | 0.7500 | +0.0500 | 120 | 20.0% | 50.0% | 0 |" in text
    assert "0.40 s (answer: feasible), which meets the 1 s target" in text
    assert (tmp_path / "t.png").stat().st_size > 0


def test_the_stamp_keeps_the_sections_measured_before() -> None:
    header = (
        "# Benchmarks\n\n_Sections 'A' re-measured on 2026-12-01 (`ltaa bench x`); 'B' "
        "re-measured on 2026-12-02 (`ltaa bench y`); the rest as generated above._\n"
    )
    assert report._stamped(header) == [
        "'A' re-measured on 2026-12-01 (`ltaa bench x`)",
        "'B' re-measured on 2026-12-02 (`ltaa bench y`)",
    ]
    assert report._stamped("# Benchmarks\n") == []
