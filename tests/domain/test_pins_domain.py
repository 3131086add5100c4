"""Pins and unavailable robots in the domain (docs/living-plans.md#pins-in-allocate)."""

from __future__ import annotations

import random

import pytest

from app.domain.cap import CapTracker, WorkloadCap
from app.domain.catalog import scenario
from app.domain.errors import DomainError, InfeasibleCapError
from app.domain.metrics import compute_metrics
from app.domain.modes import Mode
from app.domain.problem import Problem, smallest_completing_cap

BASELINE = scenario("baseline").instance
LIGHT, MEDIUM, HEAVY = 0, 1, 2


def test_without_pins_the_problem_is_todays() -> None:
    problem = Problem.build(BASELINE, Mode.BALANCED)
    assert problem.cap == WorkloadCap(36, 3, 4)
    assert problem.pinned == {} and problem.unavailable == frozenset()
    assert problem.available == (0, 1, 2)
    assert problem.free_tasks == tuple(range(36))
    assert problem.initial_loads == (0, 0, 0)
    assert problem.balance_scope is None
    assert [problem.remaining_after(t) for t in (0, 17, 35)] == [35, 18, 0]
    assert [problem.allocated_before(t) for t in (0, 17, 35)] == [0, 17, 35]


def test_heavy_unavailable_after_task_17() -> None:
    # The paper's resume point: tasks 0-17 done, 6 of them by heavy, which then breaks down.
    pins = {t: (LIGHT, MEDIUM, HEAVY)[t % 3] for t in range(18)}
    problem = Problem.build(BASELINE, Mode.BALANCED, pinned=pins, unavailable=[HEAVY])
    # W = (18 free + 12 pinned on light and medium) / 2 available robots = 15.
    assert problem.cap.target == problem.target == 15
    assert problem.cap.max_deviation == 5  # the mode default for the new W: ceil(15 / 3)
    assert (problem.cap.lower, problem.cap.upper) == (10, 20)
    assert problem.available == (LIGHT, MEDIUM)
    assert problem.unavailable == frozenset({HEAVY})
    assert problem.initial_loads == (6, 6, 0)
    assert problem.free_tasks == tuple(range(18, 36))
    assert problem.remaining_after(17) == 18 and problem.remaining_after(18) == 17
    assert problem.allocated_before(18) == 18 and problem.allocated_before(30) == 30
    assert problem.cap.feasible_robots(problem.initial_loads, 17) == [LIGHT, MEDIUM]
    assert not problem.cap.allows(problem.initial_loads, HEAVY, 17)
    # Heavy's six pins are outside the balance: the final check ignores them.
    assert problem.cap.respected_by([15, 15, 6])
    assert not problem.cap.respected_by([21, 9, 6])


def test_pins_in_the_middle_of_the_queue() -> None:
    problem = Problem.build(BASELINE, Mode.SUCCESS_FOCUSED, pinned={5: MEDIUM, 2: LIGHT})
    assert list(problem.pinned.items()) == [(2, LIGHT), (5, MEDIUM)]
    assert problem.free_tasks == (0, 1, 3, 4, *range(6, 36))
    assert problem.remaining_after(0) == 33 and problem.remaining_after(2) == 32
    assert problem.allocated_before(0) == 2 and problem.allocated_before(3) == 4
    assert problem.allocated_before(6) == 6
    full = problem.complete([HEAVY] * 34)
    assert full[2] == LIGHT and full[5] == MEDIUM and full.count(HEAVY) == 34
    with pytest.raises(ValueError, match="34 free tasks"):
        problem.complete([HEAVY] * 36)


def test_metrics_measure_balance_over_the_available_robots() -> None:
    pins = dict.fromkeys(range(6), HEAVY)
    problem = Problem.build(BASELINE, Mode.BALANCED, pinned=pins, unavailable=[HEAVY])
    assignment = problem.complete([LIGHT] * 15 + [MEDIUM] * 15)
    metrics = compute_metrics(BASELINE, assignment, scope=problem.balance_scope)
    assert metrics.workload == {"light": 15, "medium": 15, "heavy": 6}
    assert metrics.balance_score == 100.0 and metrics.max_deviation == 0.0
    assert metrics.jain_index == pytest.approx(1.0)
    everyone = compute_metrics(BASELINE, assignment)
    assert everyone.expected_success == metrics.expected_success
    assert everyone.balance_score < 100.0  # today's view: heavy's 6 against W = 12


def test_pins_that_break_the_cap_name_the_smallest_cap_that_works() -> None:
    pins = dict.fromkeys(range(18), LIGHT)
    with pytest.raises(InfeasibleCapError) as err:
        Problem.build(BASELINE, Mode.BALANCED, pinned=pins)
    assert err.value.field == "pinned" and err.value.code == "infeasible_cap"
    assert "18 tasks on robot 'light'" in err.value.message
    assert err.value.suggested_max_deviation == 6
    assert (
        "max_deviation that admits a completion" in err.value.message and " 6" in err.value.message
    )
    assert Problem.build(BASELINE, Mode.BALANCED, 6, pinned=pins).cap.upper == 18
    with pytest.raises(InfeasibleCapError):
        Problem.build(BASELINE, Mode.BALANCED, 5.9, pinned=pins)


def test_a_fractional_smallest_cap_reads_as_typed() -> None:
    # 35 tasks over 2 available robots: W = 17.5, so no cap below 0.5 admits any loads.
    with pytest.raises(InfeasibleCapError) as err:
        Problem.build(BASELINE, Mode.BALANCED, 0.1, pinned={0: LIGHT}, unavailable=[LIGHT])
    assert err.value.field == "max_deviation"
    assert err.value.suggested_max_deviation == 0.5
    # W = 35/3: the bounds move at multiples of 1/3; 2/3 is rounded up to 0.667.
    three = {0: HEAVY}
    cap = WorkloadCap(35, 3, 0)
    assert smallest_completing_cap(cap, [0, 0, 0], 35) == 0.667
    Problem.build(BASELINE, Mode.BALANCED, 0.667, pinned=three, unavailable=[HEAVY])


@pytest.mark.parametrize(
    ("pinned", "unavailable", "field", "words"),
    [
        ({36: 0}, (), "pinned", "task index 36"),
        ({-1: 0}, (), "pinned", "task index -1"),
        ({0: 3}, (), "pinned", "robot index 3"),
        ({}, (5,), "unavailable", "robot index 5"),
        ({}, (0, 1, 2), "unavailable", "no robot is left"),
    ],
)
def test_bad_pins_name_the_field(
    pinned: dict[int, int], unavailable: tuple[int, ...], field: str, words: str
) -> None:
    with pytest.raises(DomainError) as err:
        Problem.build(BASELINE, Mode.BALANCED, pinned=pinned, unavailable=unavailable)
    assert err.value.field == field
    assert words in err.value.message


@pytest.mark.parametrize("seed", range(30))
def test_smallest_completing_cap_is_the_least(seed: int) -> None:
    rng = random.Random(seed)
    n_robots = rng.randint(1, 4)
    n_free = rng.randint(0, 12)
    loads = [rng.randint(0, 8) for _ in range(n_robots)]
    cap = WorkloadCap(n_free + sum(loads), n_robots, 0)
    best = smallest_completing_cap(cap, loads, n_free)
    assert WorkloadCap(cap.n_tasks, n_robots, best).can_complete(loads, n_free)
    for smaller in (best - 0.001, best - 0.01, best / 2):
        if smaller >= 0 and smaller != best:
            assert not WorkloadCap(cap.n_tasks, n_robots, smaller).can_complete(loads, n_free)


@pytest.mark.parametrize("seed", range(20))
def test_cap_tracker_agrees_with_the_cap_given_pins(seed: int) -> None:
    rng = random.Random(seed)
    r = rng.randint(2, 5)
    off = frozenset(rng.sample(range(r), rng.randint(1, r - 1)))
    start = [0 if i in off else rng.randint(0, 3) for i in range(r)]
    free = rng.randint(0, 20)
    cap = WorkloadCap(free + sum(start), r - len(off), rng.choice([0, 0.5, 1, 2, 3]), off)
    if not cap.can_complete(start, free):
        return
    tracker, loads = CapTracker(cap, start), list(start)
    assert tracker.remaining == free
    for t in range(free):
        allowed = [i for i in range(r) if tracker.allows(i)]
        assert allowed == cap.feasible_robots(loads, free - t - 1)
        assert not off & set(allowed)
        choice = rng.choice(allowed)
        tracker.assign(choice)
        loads[choice] += 1
    assert cap.respected_by(loads)
