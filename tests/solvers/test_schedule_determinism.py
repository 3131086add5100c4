"""The scheduler's second round (docs/schedules.md#deterministic-search, #anytime, #bounds):
the model chosen by its real size, deterministic answers, a larger budget never answers
longer, the plain textbook model agrees on proven optima, every path's plan passes the
feasibility check, and the answer names its budget and what bounds its bound. Small
instances and short deterministic budgets: the large path is forced on small sites by
lowering its threshold."""

from __future__ import annotations

import dataclasses

import pytest

from app.domain.catalog import timed_scenario
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.list_schedule import list_schedule
from app.domain.scheduling.schedule import Schedule
from app.solvers.cpsat import search
from app.solvers.cpsat.common import DET_PER_S, time_free_optimum
from app.solvers.registry import get_solver
from app.solvers.timed_guidance import GUIDANCE_TIME_LIMIT_S, GuidancePlan, plan_guidance
from benchmarks.fjs import DATA, Shop, plain_model_makespan, read_fjs, shop_instance
from benchmarks.timed_instances import construction_site
from tests.support.timed_support import two_zone_site


def shop_problem(shop: Shop) -> Problem:
    return Problem.build(shop_instance(shop), Mode.BALANCED, uncapped=True)


def placed(schedule: Schedule) -> list[tuple[int, float]]:
    return [(s.robot, s.start) for s in schedule.slots]


@pytest.fixture
def large_path(monkeypatch: pytest.MonkeyPatch) -> None:
    monkeypatch.setattr(search, "EXACT_LIMIT", 0)


def test_the_model_is_chosen_by_what_it_builds() -> None:
    mk04 = shop_problem(read_fjs(DATA / "mk04.fjs"))
    # No zones: one presence literal per (operation, machine able), no travel literal.
    assert search.model_size(mk04) == (172, 0) and search.fits_exact(mk04)
    site = construction_site(200, 20, seed=0)
    assert not search.fits_exact(Problem.build(site))
    one_zone = dataclasses.replace(
        site,
        tasks=tuple(dataclasses.replace(t, zone=None) for t in site.tasks),
        robots=tuple(dataclasses.replace(r, zone=None) for r in site.robots),
        travel=None,
    )
    assert search.model_size(Problem.build(one_zone)) == (4000, 0)


def test_the_same_request_gives_the_same_answer(large_path: None) -> None:
    exact = Problem.build(timed_scenario("baseline_timed").instance)
    monkey_large = Problem.build(construction_site(36, 3, seed=1))
    for problem, limit in ((exact, 0.5), (monkey_large, 1.0)):
        first = search.solve_schedule(problem, time_limit_s=limit)
        again = search.solve_schedule(problem, time_limit_s=limit)
        assert placed(first.schedule) == placed(again.schedule)
        assert (first.bound, first.bound_source) == (again.bound, again.bound_source)
        assert first.budget == again.budget


def test_a_larger_budget_continues_the_smaller_one(large_path: None) -> None:
    problem = Problem.build(construction_site(36, 3, seed=2))
    small = search.solve_schedule(problem, time_limit_s=1.5)
    large = search.solve_schedule(problem, time_limit_s=3.0)
    assert "LNS" in large.model
    assert large.makespan <= small.makespan
    # The smaller budget's answer is the point the larger run's trajectory has reached
    # with that budget.
    reached = [p for p in large.trajectory if p[0] <= 1.5 * DET_PER_S + 1e-6]
    assert reached and reached[-1][3] == small.makespan
    makespans = [p[3] for p in large.trajectory]
    assert makespans == sorted(makespans, reverse=True)


def test_the_plain_model_and_the_service_agree_on_proven_optima() -> None:
    mk01 = read_fjs(DATA / "mk01.fjs")
    mk04 = read_fjs(DATA / "mk04.fjs")
    small = Shop("mk04-first-5-jobs", mk04.n_machines, mk04.jobs[:5])
    for shop in (mk01, small):
        plain = plain_model_makespan(shop, time_limit_s=20, workers=1)
        ours = get_solver("schedule").solve(shop_problem(shop), options={"time_limit_s": 10})
        assert plain.status == "OPTIMAL" and ours.details["status"] == "optimal"
        assert ours.details["objective_value"] == plain.makespan
        assert "no travel" in ours.details["model"]


def test_every_path_passes_the_feasibility_check(large_path: None) -> None:
    small = Problem.build(construction_site(36, 3, seed=0))
    band_200 = Problem.build(construction_site(200, 20, seed=0))
    for problem in (small, band_200):
        assert check_schedule(problem, list_schedule(problem, time_free_optimum(problem))) == []
    large = search.solve_schedule(small, time_limit_s=1.0)
    assert "large-instance path" in large.model and check_schedule(small, large.schedule) == []
    big = search.solve_schedule(band_200, time_limit_s=1.0)
    assert check_schedule(band_200, big.schedule) == []


def test_the_exact_path_passes_the_feasibility_check() -> None:
    problem = Problem.build(construction_site(36, 3, seed=0))
    out = search.solve_schedule(problem, time_limit_s=1.0)
    assert out.model.startswith("exact") and check_schedule(problem, out.schedule) == []


def test_the_answer_names_its_budget_and_what_bounds_its_bound() -> None:
    problem = Problem.build(two_zone_site())
    details = get_solver("schedule").solve(problem, options={"time_limit_s": 2}).details
    assert details["status"] == "optimal" and details["bound_source"] == "proven optimal"
    budget = details["budget"]
    assert budget["deterministic_budget"] == pytest.approx(2 * DET_PER_S)
    assert budget["workers"] == 1 and budget["seed"] == 0 and budget["wall_cut"] is False
    assert details["bounds"]["critical path (shortest durations)"] > 0
    mk02 = shop_problem(read_fjs(DATA / "mk02.fjs"))
    short = search.solve_schedule(mk02, time_limit_s=0.2)
    assert short.bound_source in short.bounds and short.bound == pytest.approx(
        min(short.makespan, short.bounds[short.bound_source])
    )


def test_the_guidance_plan_records_its_budget() -> None:
    plan = plan_guidance(Problem.build(two_zone_site()))
    assert plan.budget["time_limit_s"] == GUIDANCE_TIME_LIMIT_S
    assert plan.budget["deterministic_budget"] == pytest.approx(GUIDANCE_TIME_LIMIT_S * DET_PER_S)
    stored = GuidancePlan.from_json(plan.as_json())
    assert stored == plan and stored.budget == plan.budget
