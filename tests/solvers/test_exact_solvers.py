"""Exact solvers agree with each other (and with brute force) on random small instances."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, event, given, settings
from hypothesis import strategies as st

from app.domain.catalog import scenario
from app.domain.errors import DomainError, InfeasibleCapError
from app.domain.metrics import expected_success, workload
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.solvers.registry import get_solver
from app.solvers.tiebreak import deviation_units

EXACT = ("brute_force", "dp", "optimal")
FEATURES = ("heavy", "dexterous", "careful")


@st.composite
def instances(draw: st.DrawFn) -> tuple[Instance, float | None]:
    n_robots = draw(st.integers(1, 3))
    n_tasks = draw(st.integers(1, 7 if n_robots == 3 else 9))
    # Two-decimal rates make exact ties common, which is where tie-breaks go wrong.
    rate = st.one_of(st.integers(0, 100).map(lambda x: x / 100), st.floats(0, 1))
    robots = tuple(
        Robot(name=f"r{i}", success={f: draw(rate) for f in FEATURES}) for i in range(n_robots)
    )
    tasks = tuple(
        Task(
            id=t,
            name=f"t{t}",
            features=tuple(
                draw(st.lists(st.sampled_from(FEATURES), min_size=1, max_size=3, unique=True))
            ),
        )
        for t in range(n_tasks)
    )
    cap = draw(st.one_of(st.none(), st.integers(0, 4), st.floats(0, 4).map(lambda x: round(x, 1))))
    return Instance(tasks=tasks, robots=robots), cap


@settings(max_examples=250, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(instances())
def test_exact_solvers_agree_with_brute_force(case: tuple[Instance, float | None]) -> None:
    instance, cap = case
    # An explicit cap of None means "mode default"; success_focused's default is no cap.
    mode = Mode.SUCCESS_FOCUSED if cap is None else Mode.BALANCED
    try:
        problem = Problem.build(instance, mode, cap)
    except InfeasibleCapError as exc:
        assert exc.field == "max_deviation"
        assert "raise max_deviation" in exc.message
        return
    results = {}
    for name in EXACT:
        assignment = get_solver(name).solve(problem).assignment
        loads = workload(assignment, instance.n_robots)
        assert problem.cap.respected_by(loads), name
        results[name] = (
            expected_success(instance, assignment),
            deviation_units(loads, instance.n_tasks),
        )
    reference = results["brute_force"]
    for name, (es, dev) in results.items():
        assert es == pytest.approx(reference[0], abs=1e-7), name
        assert dev == reference[1], f"{name} breaks the deviation tie-break"


@pytest.mark.parametrize("name", EXACT)
def test_exact_solvers_refuse_an_infeasible_cap(name: str) -> None:
    instance = Instance(
        tasks=tuple(Task(id=i, name=str(i), features=("heavy",)) for i in range(4)),
        robots=(Robot("a", {"heavy": 0.5}), Robot("b", {"heavy": 0.9}), Robot("c", {"heavy": 1})),
    )
    with pytest.raises(InfeasibleCapError) as err:
        get_solver(name).solve(Problem.build(instance, Mode.BALANCED, 0))
    assert "max_deviation" in str(err.value)


@pytest.mark.parametrize(
    ("mode", "expected"),
    [
        (Mode.SUCCESS_FOCUSED, 0.830556),
        (Mode.BALANCED, 0.786111),
        (Mode.AGGRESSIVE_BALANCE, 0.769444),
    ],
)
@pytest.mark.parametrize("name", ["dp", "optimal"])
def test_baseline_scenario_optimum(name: str, mode: Mode, expected: float) -> None:
    problem = Problem.build(scenario("baseline").instance, mode)
    assignment = get_solver(name).solve(problem).assignment
    assert expected_success(problem.instance, assignment) == pytest.approx(expected, abs=5e-7)


def test_default_caps_match_the_spec() -> None:
    instance = scenario("baseline").instance
    assert Problem.build(instance, Mode.SUCCESS_FOCUSED).cap.max_deviation is None
    assert Problem.build(instance, Mode.BALANCED).cap.max_deviation == 4
    assert Problem.build(instance, Mode.AGGRESSIVE_BALANCE).cap.max_deviation == 1


def test_brute_force_refuses_large_spaces_with_the_count() -> None:
    instance = scenario("baseline").instance
    with pytest.raises(DomainError) as err:
        get_solver("brute_force").solve(Problem.build(instance, Mode.BALANCED))
    assert err.value.field == "tasks"
    assert "3^36" in err.value.message


def test_optimal_handles_large_instances() -> None:
    robots = tuple(
        Robot(f"r{i}", {f: ((i * 7 + j * 3) % 10) / 10 for j, f in enumerate(FEATURES)})
        for i in range(50)
    )
    tasks = tuple(
        Task(
            id=t,
            name=str(t),
            features=tuple(dict.fromkeys((FEATURES[t % 3], FEATURES[(t // 3) % 3]))),
        )
        for t in range(10_000)
    )
    problem = Problem.build(Instance(tasks=tasks, robots=robots), Mode.BALANCED)
    assignment = get_solver("optimal").solve(problem).assignment
    assert len(assignment) == 10_000
    assert problem.cap.respected_by(workload(assignment, 50))


def test_near_ties_are_judged_alike_by_every_exact_solver() -> None:
    # 1e-9 apart: once a "tie" for dp/brute force but a win for the flow's integer costs.
    instance = Instance(
        tasks=(Task(1, "a", ("heavy",)), Task(2, "b", ("heavy",))),
        robots=(Robot("r0", {"heavy": 0.0}), Robot("r1", {"heavy": 1e-9})),
    )
    problem = Problem.build(instance, Mode.SUCCESS_FOCUSED)
    loads = {name: workload(get_solver(name).solve(problem).assignment, 2) for name in EXACT}
    assert loads["brute_force"] == loads["dp"] == loads["optimal"]


@st.composite
def pinned_instances(
    draw: st.DrawFn,
) -> tuple[Instance, float | None, dict[int, int], frozenset[int]]:
    instance, cap = draw(instances())
    n, r = instance.n_tasks, instance.n_robots
    # Per task: not pinned, or pinned on a robot; piling pins on one robot is how pins
    # come to break a cap, so that is drawn often too.
    one_robot = draw(st.one_of(st.none(), st.integers(0, r - 1)))
    robot = st.integers(0, r - 1) if one_robot is None else st.just(one_robot)
    choices = draw(st.lists(st.one_of(st.none(), robot), min_size=n, max_size=n))
    pins = {t: c for t, c in enumerate(choices) if c is not None}
    off = draw(st.frozensets(st.integers(0, r - 1), max_size=r - 1))
    # Tight caps too, which pins break most often.
    cap = draw(st.one_of(st.just(cap), st.sampled_from([0, 0.5, 1])))
    return instance, cap, pins, off


@settings(max_examples=400, deadline=None, suppress_health_check=[HealthCheck.too_slow])
@given(pinned_instances())
def test_exact_solvers_agree_given_pins(
    case: tuple[Instance, float | None, dict[int, int], frozenset[int]],
) -> None:
    instance, cap, pins, off = case
    mode = Mode.SUCCESS_FOCUSED if cap is None else Mode.BALANCED
    try:
        problem = Problem.build(instance, mode, cap, pinned=pins, unavailable=off)
    except InfeasibleCapError as exc:
        if not pins and not off:  # today's problem, today's message
            assert exc.suggested_max_deviation is None and "raise max_deviation" in exc.message
            return
        event(f"infeasible ({exc.field})")
        # The suggested cap is the least that admits a completion given the pins...
        suggested = exc.suggested_max_deviation
        assert suggested is not None and f"{suggested:g}" in exc.message
        assert exc.field in ("pinned", "max_deviation")
        if suggested >= 0.001:
            with pytest.raises(InfeasibleCapError):
                Problem.build(instance, mode, suggested - 0.001, pinned=pins, unavailable=off)
        # ... and the exact solvers must agree at that tightest cap too.
        problem = Problem.build(instance, mode, suggested, pinned=pins, unavailable=off)
    event("pinned" if pins else "unpinned")
    event("some unavailable" if off else "all available")
    results = {}
    for name in EXACT:
        assignment = get_solver(name).solve(problem).assignment
        assert {t: assignment[t] for t in pins} == pins, name
        assert all(assignment[t] not in off for t in problem.free_tasks), name
        loads = workload(assignment, instance.n_robots)
        assert problem.cap.respected_by(loads), name
        results[name] = (
            expected_success(instance, assignment),
            deviation_units(problem.cap.balanced(loads), problem.cap.n_tasks),
        )
    reference = results["brute_force"]
    for name, (es, dev) in results.items():
        assert es == pytest.approx(reference[0], abs=1e-7), name
        assert dev == reference[1], f"{name} breaks the deviation tie-break"


@pytest.mark.parametrize("mode", list(Mode))
@pytest.mark.parametrize("prefix", [0, 1, 12, 18, 35, 36])
def test_pinning_an_optimal_prefix_keeps_the_optimum(mode: Mode, prefix: int) -> None:
    # Re-planning with the first decisions of the optimum pinned finds the same optimum.
    instance = scenario("baseline").instance
    problem = Problem.build(instance, mode)
    optimal = get_solver("optimal").solve(problem).assignment
    best = expected_success(instance, optimal)
    pins = {t: optimal[t] for t in range(prefix)}
    # The cap stays the same one: with nobody unavailable W does not change with pins.
    again = Problem.build(instance, mode, problem.cap.max_deviation, pinned=pins)
    assert again.cap == problem.cap
    for name in ("optimal", "dp"):
        assignment = get_solver(name).solve(again).assignment
        assert assignment[:prefix] == optimal[:prefix]
        assert expected_success(instance, assignment) == pytest.approx(best, abs=1e-12), name
