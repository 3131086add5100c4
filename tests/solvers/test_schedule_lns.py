"""The large-instance path's LNS (`app/solvers/cpsat/lns.py`, `lns_model.py`): a
neighbourhood of every task is the exact model; from any start it never gets worse;
under `success_then_makespan` ES stays at the allocation optimum; the makespan objective
keeps its floor; the path answers within its limit; where the speeds decide, plans of one
makespan are ranked by their robots' ends, the latest first, before their effort; past a
neighbourhood's floating tail the tasks keep their times and the plan still fits, as do
the other robots' tasks in an exchange among a few that nothing floating comes before."""

from __future__ import annotations

import time

import pytest
from ortools.sat.python import cp_model

from app.domain.metrics import expected_success
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.list_schedule import list_schedule, sequence_schedule
from app.domain.scheduling.schedule import Schedule
from app.solvers.cpsat.common import Search, time_free_optimum
from app.solvers.cpsat.large import _candidates
from app.solvers.cpsat.lns import _ancestor_masks, _better, _retimed, improve
from app.solvers.cpsat.lns_model import Neighbourhood
from app.solvers.cpsat.outcome import Setup
from app.solvers.cpsat.search import _setup, solve_schedule
from app.solvers.registry import get_solver
from benchmarks.timed_instances import construction_site
from benchmarks.unrelated_sites import unrelated_site


def setup_of(problem: Problem, seconds: float) -> Setup:
    return _setup(problem, Search(seconds, 2, 0), None)


def site_200() -> Problem:
    return Problem.build(construction_site(200, 20, seed=0), Mode.BALANCED)


def optimal_es(problem: Problem) -> float:
    return expected_success(problem.instance, get_solver("optimal").solve(problem).assignment)


@pytest.mark.parametrize(
    "build",
    [
        lambda inst: Problem.build(inst, Mode.BALANCED),
        lambda inst: Problem.build(
            inst, Mode.BALANCED, pinned={0: 1}, pinned_starts={0: 0.0}, not_before=20
        ),
        lambda inst: Problem.build(
            inst, Mode.SUCCESS_FOCUSED, objective=Objective(ObjectiveKind.MAKESPAN, 0.5)
        ),
    ],
    ids=["plain", "pins-and-now", "makespan"],
)
@pytest.mark.parametrize("compact", [False, True], ids=["per-robot-orders", "compact"])
def test_a_neighbourhood_of_every_task_finds_the_exact_optimum(build, compact: bool) -> None:  # type: ignore[no-untyped-def]
    problem = build(construction_site(9, 3, seed=3))
    assert problem.instance.timing.has_travel  # the free pairs in other zones need orders
    exact = solve_schedule(problem, time_limit_s=20)
    assert exact.status == "optimal"
    setup = setup_of(problem, 20)
    start = list_schedule(problem, setup.feasible.best().assignment)  # type: ignore[union-attr]
    candidates = [_candidates(setup, t) for t in range(problem.instance.n_tasks)]
    everything = range(problem.instance.n_tasks)
    ancestors = _ancestor_masks(setup)
    hood = Neighbourhood(setup, start, everything, candidates, ancestors, compact=compact)
    solver = cp_model.CpSolver()
    solver.parameters.max_time_in_seconds = 20
    solver.parameters.num_workers = 2
    assert solver.status_name(solver.solve(hood.model)) == "OPTIMAL"
    schedule = _retimed(setup, *hood.read(solver))
    assert schedule is not None and check_schedule(problem, schedule) == []
    assert schedule.makespan == pytest.approx(exact.makespan)


def test_from_a_poor_start_it_only_improves_and_keeps_the_optimal_success() -> None:
    problem = site_200()
    setup = setup_of(problem, 4)
    # The time-free optimum as it comes (no dispatch): far from the best, room to improve.
    start = list_schedule(problem, time_free_optimum(problem))
    before = len(setup.feasible.found)
    report = improve(setup, [_candidates(setup, t) for t in range(200)], start=start)
    assert report is not None and report.neighbourhoods > 0
    accepted = [s for _, s in setup.feasible.found[before:]]
    assert report.improved == len(accepted) >= 1
    best = optimal_es(problem)
    previous = start
    for schedule in accepted:
        assert check_schedule(problem, schedule) == []
        # Strictly better each time: a shorter plan, or as long with earlier ends.
        assert (schedule.makespan, ends(schedule)) < (previous.makespan, ends(previous))
        assert expected_success(problem.instance, schedule.assignment) == pytest.approx(best)
        previous = schedule
    assert report.end_makespan == previous.makespan <= start.makespan


def ends(schedule: Schedule) -> float:
    return sum(s.end for s in schedule.slots)


def test_200_tasks_answer_within_the_limit_with_the_optimal_success() -> None:
    problem = site_200()
    started = time.perf_counter()
    outcome = solve_schedule(problem, time_limit_s=6)
    elapsed = time.perf_counter() - started
    # The limit is a deterministic budget (docs/schedules.md#deterministic-search): the
    # wall clock only caps it, however loaded the machine.
    budget = outcome.budget
    assert elapsed < budget["wall_cap_s"] + 5, f"{elapsed:.1f} s for a 6 s limit"
    assert budget["deterministic_used"] <= budget["deterministic_budget"] + 0.6
    assert outcome.status == "feasible" and "LNS" in outcome.model
    assert check_schedule(problem, outcome.schedule) == []
    assert outcome.expected_success == pytest.approx(optimal_es(problem), abs=1e-12)
    assert 0 < outcome.bound <= outcome.makespan
    lns = next(s for s in outcome.stages if s["stage"] == "lns")
    assert lns["objective"] == outcome.makespan <= lns["start_objective"]


def test_the_makespan_objective_keeps_its_floor_in_the_lns() -> None:
    floor = 0.7
    problem = Problem.build(
        construction_site(200, 20, seed=0),
        Mode.BALANCED,
        objective=Objective(ObjectiveKind.MAKESPAN, floor),
    )
    outcome = solve_schedule(problem, time_limit_s=5)
    assert "LNS" in outcome.model
    assert check_schedule(problem, outcome.schedule) == []
    assert expected_success(problem.instance, outcome.schedule.assignment) >= floor - 1e-12


def test_of_one_makespan_the_plan_whose_robots_end_earlier_wins_before_effort() -> None:
    # Both plans end at 20 on robot a. "spread" ends its other robots at 12 and 12 with 44
    # minutes of work; "stacked" puts both on b (20) with 40. Where the speeds decide, the
    # spread one wins though it works more: a later neighbourhood may shorten a robot
    # that ends at 12, never the makespan while two robots hold it.
    work = {"t0": {"a": 10.0}, "t1": {"a": 10.0}, "t2": {"b": 12.0}, "t3": {"b": 8.0, "c": 12.0}}
    tasks = tuple(Task(id=t, name=t, features=("w",), duration=d) for t, d in work.items())
    robots = tuple(Robot(name=r, success={"w": 0.9}) for r in "abc")
    problem = Problem.build(Instance(tasks=tasks, robots=robots), uncapped=True)
    spread = sequence_schedule(problem, [[0, 1], [2], [3]])
    stacked = sequence_schedule(problem, [[0, 1], [3, 2], []])
    assert spread.makespan == stacked.makespan == 20
    assert _better(spread, stacked, effort_first=True)
    assert not _better(stacked, spread, effort_first=True)
    assert not _better(spread, spread, effort_first=True)  # a strict order: no cycle
    # The same ends and the same work: the smaller sum of ends wins (t3's 8 minutes first).
    late_short = sequence_schedule(problem, [[0, 1], [2, 3], []])
    assert _better(stacked, late_short, effort_first=True)
    assert not _better(late_short, stacked, effort_first=True)


@pytest.mark.parametrize("tail_minutes", [0.0, 30.0, 120.0])
def test_past_the_floating_tail_tasks_keep_their_times_and_the_plan_still_fits(
    tail_minutes: float,
) -> None:
    # A window early in a plan of the second family: the tasks that start more than
    # `tail_minutes` after it are constants at their planned starts, the ones between
    # float, and the plan itself is still an answer (all variables at their hints), so
    # the neighbourhood can only keep or shorten it.
    problem = Problem.build(unrelated_site(80, 4, seed=2), Mode.BALANCED, uncapped=True)
    setup = setup_of(problem, 4)
    current = setup.feasible.best()
    assert current is not None
    candidates = [_candidates(setup, t) for t in range(problem.instance.n_tasks)]
    free = sorted(range(80), key=lambda t: (current.slots[t].start, t))[10:22]
    hi = max(current.slots[f].end for f in free)
    hood = Neighbourhood(
        setup, current, free, candidates, _ancestor_masks(setup), True, tail_minutes
    )
    later = {t for t in range(80) if t not in free and current.slots[t].start >= hi + tail_minutes}
    assert hood.later == later and later  # something past the tail on this site
    floating = [t for t in range(80) if t not in free and t not in hood.frozen]
    assert floating or tail_minutes == 0.0
    assert_kept_and_fitting(setup, current, hood, later)


def test_in_an_exchange_among_a_few_robots_what_nothing_floating_precedes_keeps_its_time() -> None:
    # A window on two of four robots: of the other robots' tasks after it, those that a
    # floating task of the two precedes (through a link or a robot's order, directly or
    # not) float, the rest are constants at their planned starts, and the plan itself is
    # still an answer, so the neighbourhood can only keep or shorten it.
    problem = Problem.build(unrelated_site(80, 4, seed=2), Mode.BALANCED, uncapped=True)
    setup = setup_of(problem, 4)
    current = setup.feasible.best()
    assert current is not None
    slots, chosen = current.slots, {0, 1}
    mine = [t for t in range(80) if slots[t].robot in chosen]
    free = sorted(mine, key=lambda t: (slots[t].start, t))[8:16]
    lo = min(slots[f].start for f in free)
    allowed = [[r for r in _candidates(setup, t) if r in chosen] for t in range(80)]
    ancestors = _ancestor_masks(setup)
    hood = Neighbourhood(setup, current, free, allowed, ancestors, True, None, chosen, True)
    # Written from the rule: everything not ended before the window floats on the two
    # robots; a task follows one that floats in its robot's order or by a link.
    tm, sequences = problem.instance.timing, current.sequences(4)
    moving = {t for t in range(80) if slots[t].robot in chosen and slots[t].end > lo}
    grown = True
    while grown:
        after = {u for t in moving for u in tm.successors[t]}
        after |= {seq[i + 1] for seq in sequences for i, t in enumerate(seq[:-1]) if t in moving}
        grown = not after <= moving
        moving |= after
    kept = {t for t in range(80) if t not in moving and slots[t].end > lo}
    assert hood.later == kept and kept and moving - set(mine)  # both kinds on this site
    assert {t for t in range(80) if t not in hood.frozen} == moving
    assert_kept_and_fitting(setup, current, hood, kept)


def assert_kept_and_fitting(
    setup: Setup, current: Schedule, hood: Neighbourhood, kept: set[int]
) -> None:
    """The `kept` tasks are constants at their planned starts (whole minutes on the second
    family: one unit of the model per minute), the plan itself is an answer (every
    variable at its hint), and CP-SAT's answer, re-timed, passes the check and is never
    longer than the plan."""
    proto = hood.model.proto
    for t in kept:
        domain = proto.variables[hood.start[t].index].domain
        assert list(domain) == [round(current.slots[t].start)] * 2
    pinned = cp_model.CpSolver()
    pinned.parameters.fix_variables_to_their_hinted_value = True
    pinned.parameters.num_workers = 1
    assert pinned.status_name(pinned.solve(hood.model)) in ("OPTIMAL", "FEASIBLE")
    solver = cp_model.CpSolver()
    solver.parameters.max_deterministic_time = 0.5
    solver.parameters.num_workers = 1
    assert solver.status_name(solver.solve(hood.model)) in ("OPTIMAL", "FEASIBLE")
    schedule = _retimed(setup, *hood.read(solver))
    assert schedule is not None and check_schedule(setup.problem, schedule) == []
    assert schedule.makespan <= current.makespan
