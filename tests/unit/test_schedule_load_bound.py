"""The large path's load bound is a lower bound (docs/schedules.md#bounds): never above the
exhaustive optimum on small timed instances (the search of test_schedule_exhaustive,
written without the app's schedulers), never above a plan the scheduler finds on a
generated site, and no weaker than the plain load LP it extends."""

from __future__ import annotations

import pytest
from hypothesis import HealthCheck, assume, given, note, settings

from app.domain.errors import DomainError
from app.domain.modes import Mode
from app.domain.objective import ObjectiveKind
from app.domain.problem import Problem
from app.solvers.cpsat.bounds import chains
from app.solvers.cpsat.common import Search
from app.solvers.cpsat.large import _candidates
from app.solvers.cpsat.load_bound import load_lower_bound
from app.solvers.cpsat.outcome import Setup
from app.solvers.cpsat.search import _setup, solve_schedule
from benchmarks.timed_instances import construction_site
from tests.unit.test_schedule_exhaustive import Case, cases, exhaustive


def bounds_of(setup: Setup) -> tuple[float, float]:
    """(the plain load LP, the LP with zone entries, first heads and last tails)."""
    problem = setup.problem
    candidates = [_candidates(setup, t) for t in range(problem.instance.n_tasks)]
    _, _, heads, tails, _ = chains(problem, setup.pairs)
    common = {"es_target": setup.es_target, "es_floor": setup.es_floor, "time_limit_s": 30.0}
    plain = load_lower_bound(problem, candidates, setup.weights, **common)  # type: ignore[arg-type]
    full = load_lower_bound(
        problem,
        candidates,
        setup.weights,
        heads=heads,
        tails=tails,
        scale=setup.scale,
        **common,  # type: ignore[arg-type]
    )
    return plain, full


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
    plain, full = bounds_of(setup)
    note(f"{problem.instance}\n{problem.cap} {dict(problem.pinned_starts)}: {plain} {full}")
    assert full <= expected[1] + 1e-6
    assert plain <= full + 1e-6


@pytest.mark.parametrize(("n", "robots", "zones"), [(36, 3, None), (200, 20, (2, 2))])
def test_never_above_a_plan_found_and_above_the_plain_lp(
    n: int, robots: int, zones: tuple[int, int] | None
) -> None:
    problem = Problem.build(construction_site(n, robots, seed=0, zones=zones), Mode.BALANCED)
    setup = _setup(problem, Search(1.0, 1, 0), None)
    plain, full = bounds_of(setup)
    found = solve_schedule(problem, time_limit_s=1)
    assert plain < full <= found.makespan
