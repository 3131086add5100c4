"""Pins on team tasks (docs/living-plans.md#pins-in-allocate): every method that forms teams keeps
a pinned team whole, and the exact ones return the optimum given the pins, checked against an
exhaustive search written in the tests (`tests.solvers.test_schedule_teams`'s enumeration of teams
and per-robot orders, with the pinned task restricted to its pinned team).

Timed: `schedule` equals the search's best (expected success, then makespan); `optimal`, `dp` and
`brute_force` equal its best expected success over the capped choices (they decide who, the
list scheduler when). Untimed: all four equal that best expected success. `greedy` and `ltaa`
(timed: on the graph's own time lines) keep the pin and answer valid teams within the cap.
"""

from __future__ import annotations

import itertools
from dataclasses import replace
from fractions import Fraction

import pytest
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st

from app.domain.errors import DomainError
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import Rule, check_schedule
from app.domain.scheduling.list_schedule import list_schedule
from app.domain.teams import team_problem
from app.solvers.base import Solution
from app.solvers.registry import get_solver
from tests.solvers.test_schedule_teams import (
    Case,
    choices,
    earliest,
    instances,
    minutes,
    plan_success,
    success,
)

Members = tuple[int, ...]


def _pinned_case(draw: st.DrawFn, instance: Instance) -> tuple[Problem, int, Members]:
    team_tasks = [t for t, task in enumerate(instance.tasks) if task.team]
    t = draw(st.sampled_from(team_tasks))
    options = choices(instance, t)
    assume(options)
    team = draw(st.sampled_from(options))
    capped = draw(st.booleans())
    # Sometimes a robot is off the site (a pinned member keeps the pin, takes nothing new).
    off = draw(st.one_of(st.just(()), st.tuples(st.integers(0, instance.n_robots - 1))))
    try:
        problem = Problem.build(
            instance,
            Mode.BALANCED if capped else Mode.SUCCESS_FOCUSED,
            1 if capped else None,
            pinned={t: team[0]},
            pinned_teams={t: team},
            unavailable=off,
        )
    except DomainError:
        assume(False)
        raise
    return problem, t, team


@st.composite
def timed_pins(draw: st.DrawFn) -> tuple[Case, int, Members]:
    instance, travel = draw(instances())
    problem, t, team = _pinned_case(draw, instance)
    return Case(problem, travel), t, team


def untimed(instance: Instance) -> Instance:
    tasks = tuple(
        replace(task, duration=None, zone=None, after=(), release=None, deadline=None)
        for task in instance.tasks
    )
    robots = tuple(replace(robot, zone=None, available=None) for robot in instance.robots)
    return Instance(tasks=tasks, robots=robots)


@st.composite
def untimed_pins(draw: st.DrawFn) -> tuple[Problem, int, Members]:
    instance, _ = draw(instances(max_tasks=5))
    return _pinned_case(draw, untimed(instance))


def staffings(problem: Problem, pinned: int, team: Members) -> list[tuple[Members, ...]]:
    """Every choice of robots per task within the cap, the pinned task on its pinned team."""
    inst = problem.instance
    per_task = [
        [team] if t == pinned else [m for m in choices(inst, t) if not set(m) & problem.unavailable]
        for t in range(inst.n_tasks)
    ]
    out = []
    for members in itertools.product(*per_task):
        loads = [sum(r in m for m in members) for r in range(inst.n_robots)]
        if problem.cap.respected_by(loads):
            out.append(members)
    return out


def plan_es(inst: Instance, members: tuple[Members, ...]) -> Fraction:
    return sum((success(inst, t, m) for t, m in enumerate(members)), Fraction(0)) / inst.n_tasks


def best_in_time(case: Case, pinned: int, team: Members) -> tuple[Fraction, float] | None:
    """The best (ES, then makespan) over staffings and per-robot orders that keep the rules."""
    inst = case.problem.instance
    best: tuple[Fraction, float] | None = None
    for members in staffings(case.problem, pinned, team):
        es = plan_es(inst, members)
        if best is not None and es < best[0]:
            continue
        mine = [[t for t, m in enumerate(members) if r in m] for r in range(inst.n_robots)]
        for orders in itertools.product(*(itertools.permutations(m) for m in mine)):
            starts = earliest(case, list(members), list(orders))
            if starts is None:
                continue
            makespan = max(s + minutes(inst, t) for t, s in enumerate(starts))
            if best is None or (es, -makespan) > (best[0], -best[1]):
                best = (es, makespan)
    return best


def assert_keeps_the_pin(problem: Problem, solution: Solution, pinned: int, team: Members) -> None:
    inst = problem.instance
    assert solution.assignment[pinned] == team[0]
    assert solution.teams[pinned] == team
    for t, task in enumerate(inst.tasks):
        if task.team is not None:
            assert team_problem(task, inst.robots, solution.teams[t]) is None
    loads = [
        sum(r in solution.teams.get(t, (a,)) for t, a in enumerate(solution.assignment))
        for r in range(inst.n_robots)
    ]
    assert problem.cap.respected_by(loads), loads
    for t in problem.free_tasks:  # nothing new for a robot off the site
        assert not set(solution.teams.get(t, (solution.assignment[t],))) & problem.unavailable


@settings(
    max_examples=25,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(timed_pins())
def test_timed_exact_methods_are_the_optimum_given_a_pinned_team(
    drawn: tuple[Case, int, Members],
) -> None:
    case, pinned, team = drawn
    p = case.problem
    note(f"{p.instance}\n{p.cap} pinned {pinned} on {team}")
    es_free = max(plan_es(p.instance, m) for m in staffings(p, pinned, team))
    for method in ("optimal", "dp", "brute_force", "greedy", "ltaa"):
        solution = get_solver(method).solve(p)
        assert_keeps_the_pin(p, solution, pinned, team)
        schedule = solution.details["schedule"]
        assert schedule is not None and schedule.slots[pinned].members == team
        assert not [v for v in check_schedule(p, schedule) if v.rule is Rule.PIN]
        if method not in ("greedy", "ltaa"):
            assert plan_success(p.instance, solution.assignment, solution.teams) == es_free
    expected = best_in_time(case, pinned, team)
    solver = get_solver("schedule")
    if expected is None:
        with pytest.raises(DomainError):
            solver.solve(p, options={"time_limit_s": 20})
        return
    solution = solver.solve(p, options={"time_limit_s": 20})
    assert_keeps_the_pin(p, solution, pinned, team)
    details = solution.details
    assert check_schedule(p, details["schedule"]) == []
    assert details["status"] == "optimal", details["stages"]
    assert details["schedule"].makespan == pytest.approx(expected[1])
    assert plan_success(p.instance, solution.assignment, solution.teams) == expected[0]


@settings(
    max_examples=30,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(untimed_pins())
def test_untimed_methods_keep_a_pinned_team_and_the_exact_ones_are_optimal(
    drawn: tuple[Problem, int, Members],
) -> None:
    p, pinned, team = drawn
    note(f"{p.instance}\n{p.cap} pinned {pinned} on {team}")
    es_free = max(plan_es(p.instance, m) for m in staffings(p, pinned, team))
    for method in ("optimal", "dp", "brute_force", "schedule", "greedy", "ltaa"):
        solution = get_solver(method).solve(p)
        assert_keeps_the_pin(p, solution, pinned, team)
        if method in ("optimal", "dp", "brute_force", "schedule"):
            es = plan_success(p.instance, solution.assignment, solution.teams)
            assert es == es_free, method


def test_a_pinned_start_holds_every_member_of_the_team() -> None:
    """A team task pinned at a start (it started) blocks each member's lane over its times:
    the list scheduler places nothing of a member's inside them
    (docs/schedules.md#teams-in-time)."""
    tasks = (
        Task(id="lift", name="Lift", features=("h",), team={"h": 2}, duration=20),
        Task(id="a", name="Carry a", features=("h",), duration=10),
        Task(id="b", name="Carry b", features=("h",), duration=10),
    )
    robots = (Robot(name="p", success={"h": 0.9}), Robot(name="q", success={"h": 0.8}))
    problem = Problem.build(
        Instance(tasks=tasks, robots=robots),
        Mode.SUCCESS_FOCUSED,
        pinned={0: 0},
        pinned_teams={0: (0, 1)},
        pinned_starts={0: 5.0},
    )
    schedule = list_schedule(problem, [0, 1, 1], {0: (0, 1)})
    lift, a, b = schedule.slots
    assert (lift.start, lift.end, lift.members) == (5.0, 25.0, (0, 1))
    # q's carries both fit around the lift: one before it cannot (10 > 5), so both go after
    assert a.start >= 25.0 and b.start >= 25.0 and check_schedule(problem, schedule) == []
    for method in ("optimal", "greedy", "schedule"):
        solution = get_solver(method).solve(problem)
        placed = solution.details["schedule"]
        assert placed.slots[0].members == (0, 1) and placed.slots[0].start == 5.0
        assert check_schedule(problem, placed) == [], method


def test_the_feasibility_check_names_a_moved_pinned_team() -> None:
    tasks = (
        Task(id="lift", name="Lift", features=("h",), team={"h": 2}, duration=20),
        Task(id="a", name="Carry", features=("h",), duration=10),
    )
    robots = tuple(Robot(name=n, success={"h": 0.5}) for n in ("p", "q", "s"))
    problem = Problem.build(
        Instance(tasks=tasks, robots=robots),
        Mode.SUCCESS_FOCUSED,
        pinned={0: 0},
        pinned_teams={0: (0, 1)},
    )
    moved = list_schedule(problem, [0, 1], {0: (0, 2)})
    pins = [v for v in check_schedule(problem, moved) if v.rule is Rule.PIN]
    assert pins and "p + q" in pins[0].message
