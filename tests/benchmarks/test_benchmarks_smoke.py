"""The benchmark modules stay importable and their helpers keep working on tiny inputs.

Not the bench itself (minutes of training): each test runs one cheap helper, so an API
change in app/ breaks here rather than at the next `make bench`.
"""

from __future__ import annotations

import dataclasses
import importlib
from pathlib import Path

import pytest

from app.domain.modes import Mode
from app.domain.problem import Problem
from benchmarks import (
    adaptation,
    durable,
    learners,
    load,
    ltaa_runs,
    paper,
    plots,
    report,
    solvers,
    storage,
)
from benchmarks.cache import solved


def test_every_section_module_exposes_run() -> None:
    for name in report.SECTIONS:
        assert callable(importlib.import_module(name).run)


def test_cached_solve_is_reused() -> None:
    first = solved("greedy")
    assert solved("greedy") is first
    assert len(first.assignment) == 36
    assert first.max_deviation == 4


def test_exact_solvers_agree_on_a_small_prefix() -> None:
    rows = solvers.exact_small_rows(n_tasks=6, repeats=1)
    assert len({row[1] for row in rows}) == 1  # same expected success for all three


def test_learner_summary_row() -> None:
    summary = learners.summarise("q_learning", [78.0, 77.0], [1.0, 2.0], optimum=78.6)
    assert summary.within == 2
    assert "met" in learners.summary_row(summary)[4]


def test_prompt_sizes_and_regret_formatting() -> None:
    problem = Problem.build(solvers.first_tasks(4), Mode.BALANCED)
    chars = ltaa_runs.sent_prompt_chars(problem)
    assert len(chars) == 4 and min(chars) > len(ltaa_runs.SYSTEM_PROMPT)
    assert ltaa_runs._points(-1e-16) == "0.00"


def test_durable_measure_on_a_tiny_run() -> None:
    measure = durable.measure_durable(solvers.first_tasks(3), runs=1)
    assert measure.n_tasks == 3 and len(measure.seconds) == 1
    assert measure.checkpoint_after_wal_checkpoint > 0


def test_storage_measure_on_a_tiny_run() -> None:
    measure = durable.measure_storage(solvers.first_tasks(3), interval_s=0.01)
    assert measure.n_tasks == 3 and measure.samples >= 1
    assert measure.peak_bytes > 0 and measure.final_bytes > 0
    big = dataclasses.replace(measure, n_tasks=10_000)
    assert "met" in storage.storage_part([measure, big])


def test_frontier_is_monotone() -> None:
    points = paper.frontier_points()
    balances = [b for _, b, _ in points]
    successes = [e for _, _, e in points]
    assert balances[0] == 100.0
    assert successes == sorted(successes)


def test_claude_part_without_a_key(monkeypatch: pytest.MonkeyPatch) -> None:
    for var in ("ANTHROPIC_API_KEY", "LTAA_ANTHROPIC_API_KEY"):
        monkeypatch.delenv(var, raising=False)
    assert "not measured" in paper.claude_part()


def test_figures_render(tmp_path: Path) -> None:
    point = plots.MethodPoint("A", 78.0, (77.0, 79.0), 77.9, (77.5, 78.3))
    plots.methods_figure([point], "t", "c", "m.png", tmp_path)
    panel = plots.Panel(["x", "y"], {"A": [1.0, 2.0]}, "v", (0, 3), {"W": 1.5}, (1.0, 2.0))
    plots.panels_figure([panel, panel], "t", "c", "p.png", tmp_path)
    plots.frontier_figure(
        [("cap 0", 100.0, 76.0), ("no cap", 0.0, 83.0)],
        [plots.PlacedPoint("A", 50.0, 79.0)],
        "t",
        "c",
        "f.png",
        tmp_path,
    )
    plots.seeds_figure({"A": [77.0, 78.0]}, 78.6, 3.0, "t", "c", "s.png", tmp_path)
    plots.hbar_figure([("A", 10.0), ("B", 100.0)], "chars", "t", "c", "h.png", tmp_path)
    plots.latency_histogram_figure({"A": [0.1, 0.2], "B": [0.5]}, "t", "c", "l.png", tmp_path)
    assert sorted(p.name for p in tmp_path.iterdir()) == [
        "f.png",
        "h.png",
        "l.png",
        "m.png",
        "p.png",
        "s.png",
    ]


def test_load_round_bookkeeping() -> None:
    bodies = load.allocate_bodies()
    assert len(bodies) == load.N_ALLOCATE
    assert {(b["solver"], b["scenario"]) for b in bodies} == {
        (s, sc) for s in load.SOLVERS for sc in load.SCENARIOS
    }
    ok = load.Call("greedy", 200, 0.1, scenario="baseline", expected_success=80.0)
    broken = load.Call("dp", 500, 0.2, '{"detail": "database is locked"}', "baseline")
    result = load.LoadResult(
        calls=[ok, broken],
        create_statuses=[202],
        runs=[{"id": "r1", "status": "failed"}],
        run_seconds=[1.0],
        allocate_wall_s=1.0,
    )
    log = '{"level": "INFO", "message": "ok"}\n{"level": "ERROR", "message": "boom"}'
    problems = load.failures(result, log)
    assert len(problems) == 4 and sum("database is locked" in p for p in problems) == 2
    assert result.latencies() == [0.1] and result.latencies("dp") == []


def test_adaptation_cases_and_figure(tmp_path: Path) -> None:
    cases = adaptation.cases()
    assert [len(c.problem.pinned) for c in cases] == [adaptation.HEAVY_AFTER, adaptation.URGENT_AT]
    assert cases[0].problem.unavailable and not cases[1].problem.unavailable
    results = adaptation.measure(cases[0], [("optimal", "optimal", {}), ("greedy", "greedy", {})])
    assert results[0].es == pytest.approx(results[0].optimum)
    assert results[1].es <= results[1].optimum + 1e-9
    adaptation.figure(results, "adaptation-test.png", tmp_path)
    assert (tmp_path / "adaptation-test.png").stat().st_size > 0


def test_site_learning_cases_differ_where_the_benchmark_says() -> None:
    from benchmarks import site_learning as sl

    assert sl.CONFIGURED["heavy"]["dexterous"] == 0.65
    assert sl.TRUE_RATES["heavy"]["dexterous"] == 0.3
    assert sl.HARD_TRUE["heavy"]["careful"] > sl.HARD_CONFIGURED["heavy"]["careful"]
    instance = sl.instance_with(sl.TRUE_RATES)
    assert instance.n_tasks == 36
    assert sl.success(sl.TRUE_RATES, "heavy", ["heavy", "dexterous"]) == (0.9 + 0.3) / 2


def test_durable_cost_reads_the_cost_per_task_from_the_polls() -> None:
    from benchmarks.durable_cost import Measure, SizeResult, growth, report

    # Polls at (tasks decided, server CPU): 9 ms a task up to 2,000, 12 ms after 8,000.
    progress = ((900, 8.1), (1_000, 9.0), (2_000, 18.0), (8_000, 72.0), (9_000, 84.0))
    late = Measure(90.0, 96.0, 5, 0.1, progress)
    assert late.cpu_per_task((0.1, 0.2), 10_000) == pytest.approx(0.009)
    assert late.cpu_per_task((0.8, 0.9), 10_000) == pytest.approx(0.012)
    assert Measure(1.0, 1.0, 1, 0.0, ((500, 4.0),)).cpu_per_task((0.1, 0.2), 10_000) is None
    assert "(**1.33×**)" in growth(SizeResult(10_000, (late,), (late,)))

    small = SizeResult(
        1_000,
        tuple(Measure(1.0, cpu) for cpu in (7.0, 8.0, 9.0, 30.0)),
        tuple(Measure(1.0, cpu) for cpu in (9.0, 10.0, 11.0, 40.0)),
    )
    assert small.memory.cpu == 8.5 and small.durable.cpu == 10.5  # medians: a burst ignored
    text = report([small, SizeResult(10_000, (Measure(90.0, 85.0),), (late,))], None)
    # 96 / 10.5 = 9.1x the small run: met; 96 / 85 = 1.13x in memory: met.
    assert "| durable 10,000 tasks ≤ 10× 1,000 tasks | 9.1× CPU" in text
    assert "| durable ≤ 1.5× in-memory CPU, 10,000 tasks (polled) | 1.13× | met |" in text


def test_team_sizes_on_a_tiny_instance(tmp_path: Path) -> None:
    from benchmarks import team_sizes as ts

    timed = ts.team_site(8, 3, seed=1)
    assert any(t.team == {"heavy": 2} for t in timed.tasks) and timed.timed
    assert not ts.team_site(8, 3, seed=1, timed=False).timed
    rows = ts.measure(((8, 3),), (0,), 0.5)
    by = {(r["timed"], r["method"]): r for r in rows}
    assert by[False, "optimal"]["es_regret"] == 0.0
    assert all(r["es"] <= by[False, "optimal"]["es"] + 1e-9 for r in rows if not r["timed"])
    timed_rows = [r for r in rows if r["timed"] and "refused" not in r]
    assert min(r["makespan_regret"] for r in timed_rows) == 0.0
    assert all(r["broken"] == 0 for r in timed_rows)
    # A method that refuses the timed instance (LTAA until it places teams) is a row, not a
    # failure; one that accepts it has a makespan.
    for label in ("LTAA unguided", "LTAA guided"):
        row = by[True, label]
        assert "refused" in row or "makespan" in row
    text = ts.body(rows, None, 0.5)
    assert "| 8 x 3 | 0 | greedy |" in text
    assert ts.figure(rows, tmp_path) == "img/team_sizes.png"
    assert (tmp_path / "team_sizes.png").exists()
