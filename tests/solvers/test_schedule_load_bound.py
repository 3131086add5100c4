"""The large path's load bound is a lower bound (docs/schedules.md#bounds): never above the
exhaustive optimum on small timed instances (the search of test_schedule_exhaustive,
written without the app's schedulers), never above a plan the scheduler finds on a
generated site, and no weaker than the plain load LP it extends."""

from __future__ import annotations

import itertools
import math

import pytest
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st
from ortools.sat.python import cp_model

from app.domain.errors import DomainError
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.solvers.cpsat.assignment_model import AssignmentModel
from app.solvers.cpsat.bounds import chains
from app.solvers.cpsat.common import Search, SuccessWeights
from app.solvers.cpsat.large import _candidates
from app.solvers.cpsat.load_bound import load_relaxation
from app.solvers.cpsat.outcome import Setup
from app.solvers.cpsat.search import _setup, solve_schedule
from app.solvers.cpsat.zone_routes import route_minutes, shortest_ways
from benchmarks.timed_instances import construction_site
from benchmarks.unrelated_sites import unrelated_site
from tests.solvers.test_schedule_exhaustive import Case, cases, exhaustive


def bounds_of(setup: Setup) -> tuple[float, float, float]:
    """(the plain load LP, the LP with zone entries, first heads and last tails, that LP
    with each robot's routes through the zones)."""
    problem = setup.problem
    candidates = [_candidates(setup, t) for t in range(problem.instance.n_tasks)]
    _, _, heads, tails, _ = chains(problem, setup.pairs)
    common = {"es_target": setup.es_target, "es_floor": setup.es_floor, "time_limit_s": 30.0}
    plain = load_relaxation(problem, candidates, setup.weights, **common).minutes  # type: ignore[arg-type]
    full, routed = (
        load_relaxation(
            problem,
            candidates,
            setup.weights,
            heads=heads,
            tails=tails,
            scale=setup.scale,
            routes=routes,
            **common,  # type: ignore[arg-type]
        ).minutes
        for routes in (False, True)
    )
    return plain, full, routed


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(cases())
def test_never_above_the_exhaustive_optimum(case: Case) -> None:
    problem = case.problem
    try:
        setup = _setup(problem, Search(1.0, 1, 0), None)
    except DomainError:  # no allocation reaches the floor: nothing to bound
        assume(False)
        raise
    kind = problem.objective.kind
    # The large path bounds the plan at the ES it holds: the time-free optimum's (when a
    # schedule reaches it) or the floor of `makespan`.
    assume(setup.es_target is not None or kind is ObjectiveKind.MAKESPAN)
    expected = exhaustive(case)
    assume(expected is not None)
    assert expected is not None
    plain, full, routed = bounds_of(setup)
    note(f"{problem.instance}\n{problem.cap} {dict(problem.pinned_starts)}: {plain} {full}")
    assert full <= routed <= expected[1] + 1e-6
    assert plain <= full + 1e-6


@pytest.mark.parametrize(("n", "robots", "zones"), [(36, 3, None), (200, 20, (2, 2))])
def test_never_above_a_plan_found_and_above_the_plain_lp(
    n: int, robots: int, zones: tuple[int, int] | None
) -> None:
    problem = Problem.build(construction_site(n, robots, seed=0, zones=zones), Mode.BALANCED)
    setup = _setup(problem, Search(1.0, 1, 0), None)
    plain, full, routed = bounds_of(setup)
    found = solve_schedule(problem, time_limit_s=1)
    assert plain < full <= routed <= found.makespan


# Zones in two groups (docs/schedules.md#bounds): A-B and C-D near each other, the groups
# further apart, so a robot that works in the other group pays its first entry into it.
GROUPED = {"A": {"B": 2, "C": 5, "D": 6}, "B": {"C": 6, "D": 7}, "C": {"D": 1}}


@st.composite
def grouped_cases(draw: st.DrawFn) -> Problem:
    names = [f"r{i}" for i in range(draw(st.integers(1, 2)))]
    robots = tuple(
        Robot(
            name=name,
            success={"x": draw(st.integers(1, 20)) / 20},
            # no start zone: the robot starts at its first task; a late shift: a robot
            # that takes nothing must not hold the bound up
            zone=draw(st.sampled_from(["A", "B", "C", "D", None])),
            available=(draw(st.sampled_from([0, 1, 3, 40])), 10_000),
        )
        for name in names
    )
    tasks = []
    for t in range(draw(st.integers(1, 5))):
        tasks.append(
            Task(
                id=t,
                name=f"t{t}",
                features=("x",),
                duration={n: draw(st.integers(1, 6)) for n in names},
                after=tuple(draw(st.lists(st.sampled_from(range(t)), unique=True, max_size=1)))
                if t
                else (),
                zone=draw(st.sampled_from("ABCD")),
                release=draw(st.one_of(st.none(), st.integers(0, 9))),
            )
        )
    instance = Instance(tasks=tuple(tasks), robots=robots, travel=GROUPED)
    kind = draw(st.sampled_from(list(ObjectiveKind)))
    return Problem.build(instance, Mode.SUCCESS_FOCUSED, objective=Objective(kind, 0.0))


def test_a_robot_that_takes_nothing_holds_no_shift() -> None:
    """One robot does the one task at minute 0; the other's shift starts at 50: the bound
    is 1, not 50 (each time line counts its shift start only if the robot works), in the
    load LP and in the CP-SAT assignment model."""
    robots = (
        Robot(name="r0", success={"x": 0.9}, zone="A", available=(0, 100)),
        Robot(name="r1", success={"x": 0.5}, zone="A", available=(50, 100)),
    )
    tasks = (Task(id=0, name="a", features=("x",), duration=1, zone="A"),)
    instance = Instance(tasks=tasks, robots=robots, travel=GROUPED)
    objective = Objective(ObjectiveKind.MAKESPAN, 0.0)  # either robot may take it
    problem = Problem.build(instance, Mode.SUCCESS_FOCUSED, objective=objective)
    setup = _setup(problem, Search(1.0, 1, 0), None)
    assert max(bounds_of(setup)) <= 1 == solve_schedule(problem, time_limit_s=1).makespan
    candidates = [_candidates(setup, t) for t in range(problem.instance.n_tasks)]
    assign = AssignmentModel(problem, setup.scale, candidates, setup.weights)
    assign.model.add(assign.es >= 0)
    assign.model.minimize(assign.makespan)
    solver = cp_model.CpSolver()
    assert solver.solve(assign.model) == cp_model.OPTIMAL
    assert setup.scale.minutes(solver.best_objective_bound) <= 1


def test_a_robot_without_a_start_zone_enters_no_first_zone() -> None:
    """Without a start zone a robot starts at its first task: C then D is 1 + 1 + 1."""
    robot = Robot(name="r", success={"x": 0.5}, zone=None, available=(0, 100))
    tasks = (
        Task(id=0, name="c", features=("x",), duration=1, zone="C"),
        Task(id=1, name="d", features=("x",), duration=1, zone="D"),
    )
    problem = Problem.build(
        Instance(tasks=tasks, robots=(robot,), travel=GROUPED), Mode.SUCCESS_FOCUSED
    )
    setup = _setup(problem, Search(1.0, 1, 0), None)
    assert max(bounds_of(setup)) <= 3 == solve_schedule(problem, time_limit_s=1).makespan


def grouped_optimum(problem: Problem, es_target: int | None, weights: SuccessWeights) -> float:
    """The shortest makespan over every assignment (at the ES the bound holds, if one) and
    every order of each robot's tasks, each at its earliest times, written from the rules:
    a task starts once its predecessors ended, its release allows and its robot is free and
    has travelled there from its last zone (its start zone first)."""
    inst = problem.instance
    tm = inst.timing
    n, best = inst.n_tasks, math.inf
    for robots in itertools.product(range(inst.n_robots), repeat=n):
        if es_target is not None and weights.of(robots) != es_target:
            continue
        mine = [[t for t in range(n) if robots[t] == r] for r in range(inst.n_robots)]
        for orders in itertools.product(*(itertools.permutations(m) for m in mine)):
            end = [math.nan] * n
            free = [float(r.available[0]) for r in inst.robots if r.available is not None]
            # a robot without a start zone starts where its first task is (no way there)
            where = [tm.robot_zone[r] for r in range(inst.n_robots)]
            position = [0] * inst.n_robots
            for _ in range(n):
                for r, order in enumerate(orders):
                    if position[r] == len(order):
                        continue
                    t = order[position[r]]
                    preds = [
                        k for k, other in enumerate(inst.tasks) if other.id in inst.tasks[t].after
                    ]
                    if any(math.isnan(end[p]) for p in preds):
                        continue
                    way = tm.travel(where[r], tm.task_zone[t])
                    start = max([free[r] + way, tm.release[t]] + [end[p] for p in preds])
                    end[t] = start + tm.duration(t, r)
                    free[r], where[r] = end[t], tm.task_zone[t]
                    position[r] += 1
            if not any(math.isnan(e) for e in end):
                best = min(best, max(end))
    return best


@settings(max_examples=60, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(grouped_cases())
def test_group_entries_never_above_the_exhaustive_optimum(problem: Problem) -> None:
    setup = _setup(problem, Search(1.0, 1, 0), None)
    assume(setup.es_target is not None or setup.es_floor is not None)
    _, full, routed = bounds_of(setup)
    expected = grouped_optimum(problem, setup.es_target, setup.weights)
    note(f"{problem.instance}: {full} {routed} vs {expected}")
    assert full <= routed + 1e-6
    assert routed <= expected + 1e-6


def test_group_entries_count_the_way_into_the_other_group() -> None:
    """One robot at A: a task in A, then one in C and one in D. Their zone entries are 1
    each (C and D are 1 apart), 5 in all with the work; the first way into the group
    {C, D} is at least 5 (from A), 4 more: the bound is the optimum, 9."""
    robot = Robot(name="r", success={"x": 0.5}, zone="A", available=(0, 100))
    tasks = (
        Task(id=0, name="a", features=("x",), duration=1, zone="A"),
        Task(id=1, name="c", features=("x",), duration=1, zone="C", after=(0,)),
        Task(id=2, name="d", features=("x",), duration=1, zone="D", after=(0,)),
    )
    problem = Problem.build(
        Instance(tasks=tasks, robots=(robot,), travel=GROUPED), Mode.SUCCESS_FOCUSED
    )
    setup = _setup(problem, Search(1.0, 1, 0), None)
    assert bounds_of(setup)[1] == grouped_optimum(problem, setup.es_target, setup.weights) == 9


def test_a_route_through_the_zones_counts_every_way_between_them() -> None:
    """One robot at A, one task in each of B, C and D. The entries charge 2 into B, 1
    into C and 1 into D, and the group {C, D} 4 more on its first entry: 8, with the
    work 11. But no route does it in 8: A-B-C-D is 2 + 6 + 1 = 9, and every other is
    longer, so the routes give the optimum, 12."""
    robot = Robot(name="r", success={"x": 0.5}, zone="A", available=(0, 100))
    tasks = tuple(
        Task(id=t, name=z.lower(), features=("x",), duration=1, zone=z) for t, z in enumerate("BCD")
    )
    problem = Problem.build(
        Instance(tasks=tasks, robots=(robot,), travel=GROUPED), Mode.SUCCESS_FOCUSED
    )
    setup = _setup(problem, Search(1.0, 1, 0), None)
    _, full, routed = bounds_of(setup)
    assert (full, routed) == (11, 12) == (11, grouped_optimum(problem, None, setup.weights))


@given(
    st.integers(1, 5).flatmap(
        lambda n: st.tuples(
            st.lists(st.lists(st.integers(0, 9), min_size=6, max_size=6), min_size=6, max_size=6),
            st.sampled_from([None, *range(6)]),
            st.lists(st.integers(0, 5), min_size=n, max_size=n, unique=True),
        )
    )
)
def test_route_minutes_are_the_shortest_walk_through_each_set(
    drawn: tuple[list[list[int]], int | None, list[int]],
) -> None:
    """Every set's route is the least over its orders of the way from the start zone (none:
    from the first) through the set, over the shortest ways between zones (a walk may
    pass through any zone)."""
    travel, home, zones = drawn
    for z in range(6):
        travel[z][z] = 0
    way = shortest_ways(travel)
    for mask, minutes in route_minutes(way, home, zones).items():
        members = [z for i, z in enumerate(zones) if mask >> i & 1]
        walks = [
            (0 if home is None else way[home][order[0]])
            + sum(way[a][b] for a, b in itertools.pairwise(order))
            for order in itertools.permutations(members)
        ]
        assert minutes == min(walks)
    for a, b, c in itertools.product(range(6), repeat=3):  # a metric, each way at most direct
        assert way[a][c] <= way[a][b] + way[b][c] and way[a][c] <= travel[a][c]


@settings(max_examples=20, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(st.integers(3, 6), st.integers(2, 3), st.integers(0, 10_000))
def test_never_above_the_exhaustive_optimum_on_the_second_family(
    n_tasks: int, n_robots: int, seed: int
) -> None:
    """Small sites of the unrelated family (docs/schedules.md#the-generator): four zones with
    random metric travel, every (task, robot) duration its own, precedence and releases."""
    assume(n_tasks <= 4 or n_robots == 2)  # the search is robots^tasks x orders
    problem = Problem.build(
        unrelated_site(n_tasks, n_robots, seed=seed), Mode.BALANCED, uncapped=True
    )
    setup = _setup(problem, Search(1.0, 1, 0), None)
    plain, full, routed = bounds_of(setup)
    expected = grouped_optimum(problem, setup.es_target, setup.weights)
    note(f"{problem.instance}: {plain} {full} {routed} vs {expected}")
    assert plain <= full <= routed + 1e-6
    assert routed <= expected + 1e-6
