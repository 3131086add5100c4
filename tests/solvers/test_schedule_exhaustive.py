"""CP-SAT's optimum equals an exhaustive search on small timed instances
(docs/schedules.md#schedulers).

The search is written here, from docs/schedules.md#schedulers, without the app's schedulers: every
assignment within the cap, every order of each robot's tasks, each timed at its earliest (a task
starts once its predecessors have ended, its robot has finished the previous task and
travelled, its release and shift allow; a pinned start is kept as it is). For a regular
objective an optimal schedule is among these. It keeps the best (ES, then makespan) or,
for `makespan`, the shortest with ES at least the floor.
"""

from __future__ import annotations

import itertools
import math
from dataclasses import dataclass

import pytest
from hypothesis import HealthCheck, assume, given, note, settings
from hypothesis import strategies as st

from app.domain.errors import DomainError
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.solvers.registry import get_solver

ZONES = ("A", "B")


@dataclass(frozen=True)
class Case:
    problem: Problem
    travel: int


@st.composite
def cases(draw: st.DrawFn) -> Case:
    n_robots = draw(st.integers(2, 3))
    n_tasks = draw(st.integers(2, 6 if n_robots == 3 else 7))
    travel = draw(st.integers(0, 6))
    names = [f"r{i}" for i in range(n_robots)]
    rate = st.integers(1, 20).map(lambda x: x * 5 / 100)
    robots = tuple(
        Robot(
            name=name,
            success={"x": draw(rate), "y": draw(rate)},
            zone=draw(st.sampled_from(ZONES)),
            available=draw(st.one_of(st.none(), st.tuples(st.integers(0, 4), st.integers(30, 60)))),
        )
        for name in names
    )
    tasks = []
    for t in range(n_tasks):
        minutes = {n: draw(st.integers(1, 9)) for n in names}
        able = draw(st.lists(st.sampled_from(names), min_size=1, max_size=n_robots, unique=True))
        earlier = list(range(t))
        tasks.append(
            Task(
                id=t,
                name=f"t{t}",
                features=tuple(draw(st.sampled_from([("x",), ("y",), ("x", "y")]))),
                duration={n: minutes[n] for n in able}
                if draw(st.booleans())
                else minutes[names[0]],
                after=tuple(draw(st.lists(st.sampled_from(earlier), unique=True, max_size=2)))
                if earlier
                else (),
                zone=draw(st.sampled_from(ZONES)),
                release=draw(st.one_of(st.none(), st.integers(0, 8))),
                deadline=draw(st.one_of(st.none(), st.integers(10, 40))),
            )
        )
    try:
        instance = Instance(tasks=tuple(tasks), robots=robots, travel={"A": {"B": travel}})
    except DomainError:
        assume(False)
        raise
    pinned: dict[int, int] = {}
    starts: dict[int, float] = {}
    if draw(st.booleans()):
        t = draw(st.integers(0, n_tasks - 1))
        pinned[t] = draw(st.sampled_from([r for r in range(n_robots) if instance.eligible[t, r]]))
        if draw(st.booleans()):
            starts[t] = float(draw(st.integers(0, 12)))
    capped = draw(st.booleans())
    kind = draw(st.sampled_from(list(ObjectiveKind)))
    floor = draw(st.sampled_from([0.0, 0.4, 0.6])) if kind is ObjectiveKind.MAKESPAN else 0.0
    try:
        problem = Problem.build(
            instance,
            Mode.BALANCED if capped else Mode.SUCCESS_FOCUSED,
            1 if capped else None,
            pinned=pinned,
            pinned_starts=starts,
            objective=Objective(kind, floor),
        )
    except DomainError:
        assume(False)
        raise
    return Case(problem, travel)


def earliest_times(
    case: Case, robots: list[int], orders: list[tuple[int, ...]]
) -> list[float] | None:
    """Earliest starts for these per-robot orders, or None if they cannot be kept."""
    problem, inst = case.problem, case.problem.instance
    n = inst.n_tasks
    start: list[float | None] = [None] * n
    end: list[float] = [0.0] * n
    position = [0] * len(orders)
    free = [float(r.available[0]) if r.available else 0.0 for r in inst.robots]
    where = [r.zone for r in inst.robots]
    for _ in range(n):
        moved = False
        for r, order in enumerate(orders):
            if position[r] == len(order):
                continue
            t = order[position[r]]
            task = inst.tasks[t]
            fixed = problem.pinned_starts.get(t)
            preds = [k for k, other in enumerate(inst.tasks) if other.id in task.after]
            if fixed is None and any(start[p] is None for p in preds):
                continue
            minutes = inst.timing.duration(t, r)
            move = 0 if where[r] == task.zone else case.travel
            ready = free[r] + move
            if fixed is not None:
                # a fact: only its robot's previous task and the travel can contradict it
                if fixed < ready and position[r] > 0:
                    return None
                s = fixed
            else:
                s = max(
                    [ready, float(task.release or 0), problem.not_before] + [end[p] for p in preds]
                )
                shift = inst.robots[r].available
                if task.deadline is not None and s + minutes > task.deadline:
                    return None
                if shift is not None and s + minutes > shift[1]:
                    return None
            start[t], end[t] = s, s + minutes
            free[r], where[r] = max(free[r], end[t]), task.zone  # travel within the shift
            position[r] += 1
            moved = True
        if not moved:
            break
    if any(s is None for s in start):
        return None  # the orders contradict the precedence
    return [float(s) for s in start if s is not None]


def exhaustive(case: Case) -> tuple[int, float] | None:
    """The best (ES in 1/1000 units, makespan) for the problem's objective, or None."""
    problem, inst = case.problem, case.problem.instance
    options = []
    for t in range(inst.n_tasks):
        if t in problem.pinned:
            options.append([problem.pinned[t]])
        else:
            options.append([r for r in problem.available if inst.eligible[t, r]])
    best: tuple[int, float] | None = None
    floor = problem.objective.min_expected_success
    for robots in itertools.product(*options):
        loads = [robots.count(r) for r in range(inst.n_robots)]
        if not problem.cap.respected_by(loads):
            continue
        es = round(1000 * sum(inst.success[t, r] for t, r in enumerate(robots)))
        if problem.objective.kind is ObjectiveKind.MAKESPAN and es < math.ceil(
            1000 * floor * inst.n_tasks - 1e-6
        ):
            continue
        mine = [[t for t in range(inst.n_tasks) if robots[t] == r] for r in range(inst.n_robots)]
        for orders in itertools.product(*(itertools.permutations(m) for m in mine)):
            starts = earliest_times(case, list(robots), list(orders))
            if starts is None:
                continue
            makespan = max(s + inst.timing.duration(t, robots[t]) for t, s in enumerate(starts))
            if best is None:
                best = (es, makespan)
            elif problem.objective.kind is ObjectiveKind.SUCCESS_THEN_MAKESPAN:
                best = max(best, (es, makespan), key=lambda b: (b[0], -b[1]))
            elif makespan < best[1]:
                best = (es, makespan)
    return best


@settings(
    max_examples=40,
    deadline=None,
    suppress_health_check=[HealthCheck.too_slow, HealthCheck.filter_too_much],
)
@given(cases())
def test_cp_sat_matches_the_exhaustive_search(case: Case) -> None:
    p = case.problem
    note(f"{p.instance}\n{p.mode} {p.cap} {dict(p.pinned)} {dict(p.pinned_starts)} {p.objective}")
    expected = exhaustive(case)
    solver = get_solver("schedule")
    if expected is None:
        with pytest.raises(DomainError) as err:
            solver.solve(case.problem, options={"time_limit_s": 20})
        assert err.value.code in ("no_schedule", "infeasible_cap"), err.value.message
        return
    solution = solver.solve(case.problem, options={"time_limit_s": 20})
    details = solution.details
    schedule = details["schedule"]
    assert check_schedule(case.problem, schedule) == []
    assert details["status"] == "optimal", details["stages"]
    assert schedule.makespan == pytest.approx(expected[1])
    inst = case.problem.instance
    es = round(1000 * sum(inst.success[t, r] for t, r in enumerate(solution.assignment)))
    if case.problem.objective.kind is ObjectiveKind.SUCCESS_THEN_MAKESPAN:
        assert es == expected[0]
