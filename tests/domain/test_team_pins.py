"""Pinned teams in a problem (docs/living-plans.md#teams-in-a-revision): a pin keeps the whole team,
each available member carries its load, W counts them; a pinned team must be valid; a free team
that the available robots can no longer form is refused naming the task and the feature; the exact
solver plans the rest around the pinned team, checked against an exhaustive search here."""

from __future__ import annotations

import itertools

import pytest

from app.domain.errors import DomainError
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.solvers.registry import get_solver

CRANE, ARM, LIFTER, HOIST = range(4)


def instance() -> Instance:
    return Instance(
        tasks=(
            Task("beam", "Lift beam", ("heavy",), team={"heavy": 2}),
            Task("panel", "Fix panel", ("heavy", "careful"), team={"heavy": 1, "careful": 1}),
            Task("sweep", "Sweep", ("careful",)),
            Task("truss", "Raise truss", ("heavy",), team={"heavy": 2}),
        ),
        robots=(
            Robot("crane", {"heavy": 0.9, "careful": 0.2}, skills=("heavy",)),
            Robot("arm", {"heavy": 0.3, "careful": 0.95}, skills=("careful",)),
            Robot("lifter", {"heavy": 0.8, "careful": 0.4}),
            Robot("hoist", {"heavy": 0.7, "careful": 0.5}),
        ),
    )


def test_a_pinned_team_loads_each_available_member() -> None:
    problem = Problem.build(
        instance(), Mode.SUCCESS_FOCUSED, pinned={0: CRANE}, pinned_teams={0: (CRANE, LIFTER)}
    )
    assert problem.initial_loads == (1, 0, 1, 0)
    assert problem.free_tasks == (1, 2, 3) and problem.cap.n_tasks == 7  # 2 pinned + 5 free
    # A member taken off the site keeps the pin, carries no load, and W loses it.
    off = Problem.build(
        instance(),
        Mode.SUCCESS_FOCUSED,
        pinned={0: CRANE},
        pinned_teams={0: (CRANE, LIFTER)},
        unavailable=[LIFTER],
    )
    assert off.initial_loads == (1, 0, 0, 0) and off.cap.n_tasks == 6


@pytest.mark.parametrize(
    ("team", "why"),
    [
        ((LIFTER, CRANE), "does not match its pin"),  # the first member is the pin's robot
        ((CRANE, CRANE), "distinct"),
        ((CRANE,), "1 members for 2 units"),
    ],
)
def test_a_pinned_team_must_be_the_tasks_whole_valid_team(team: tuple[int, ...], why: str) -> None:
    with pytest.raises(DomainError) as err:
        Problem.build(instance(), Mode.BALANCED, pinned={0: CRANE}, pinned_teams={0: team})
    assert err.value.field == "pinned" and why in err.value.message


def test_a_pinned_team_stays_whatever_its_members_rates_say_now() -> None:
    # The arm cannot cover `heavy` (skills); pinned, the decided team is kept as it was.
    problem = Problem.build(
        instance(), Mode.BALANCED, pinned={0: CRANE}, pinned_teams={0: (CRANE, ARM)}
    )
    assert problem.pinned_teams[0] == (CRANE, ARM) and problem.initial_loads == (1, 1, 0, 0)


def test_a_team_task_pinned_without_its_team_is_still_refused() -> None:
    with pytest.raises(DomainError) as err:
        Problem.build(instance(), Mode.BALANCED, pinned={0: CRANE})
    assert err.value.code == "team_pin"


def test_a_free_team_the_available_robots_cannot_form_names_task_and_feature() -> None:
    with pytest.raises(DomainError) as err:
        Problem.build(instance(), Mode.BALANCED, unavailable=[CRANE, HOIST])
    assert err.value.code == "team_unformable" and err.value.field == "tasks.0.team.heavy"
    message = err.value.message
    assert "'beam'" in message and "'heavy'" in message and "only 1 can (lifter)" in message
    assert "crane, hoist unavailable" in message


def _units(task: Task) -> list[str]:
    return [f for f, c in (task.team or {}).items() for _ in range(c)]


def _staffing_success(inst: Instance, t: int, members: tuple[int, ...]) -> float:
    task = inst.tasks[t]
    units = _units(task)
    if not units:
        rates = inst.robots[members[0]].success
        return sum(rates[f] for f in task.features) / len(task.features)
    return sum(inst.robots[r].success[f] for r, f in zip(members, units, strict=True)) / len(units)


def _may_cover(robot: Robot, feature: str) -> bool:
    return robot.skills is None or feature in robot.skills


def _exhaustive(problem: Problem) -> float:
    """Best total success of the free tasks by trying every staffing (uncapped)."""
    inst = problem.instance
    options: list[list[tuple[int, ...]]] = []
    for t in problem.free_tasks:
        units = _units(inst.tasks[t])
        if not units:
            options.append([(r,) for r in problem.available])
            continue
        options.append(
            [
                m
                for m in itertools.permutations(problem.available, len(units))
                if all(_may_cover(inst.robots[r], f) for r, f in zip(m, units, strict=True))
            ]
        )
    return max(
        sum(_staffing_success(inst, t, m) for t, m in zip(problem.free_tasks, choice, strict=True))
        for choice in itertools.product(*options)
    )


def test_optimal_plans_the_rest_around_a_pinned_team() -> None:
    problem = Problem.build(
        instance(),
        Mode.SUCCESS_FOCUSED,
        None,
        uncapped=True,
        pinned={0: CRANE},
        pinned_teams={0: (CRANE, LIFTER)},
        unavailable=[LIFTER],
    )
    solution = get_solver("optimal").solve(problem)
    assert solution.assignment[0] == CRANE
    free = list(problem.free_tasks)
    for t in free:
        members = solution.teams.get(t, (solution.assignment[t],))
        assert LIFTER not in members
    got = sum(
        _staffing_success(problem.instance, t, solution.teams.get(t, (solution.assignment[t],)))
        for t in free
    )
    assert got == pytest.approx(_exhaustive(problem))
