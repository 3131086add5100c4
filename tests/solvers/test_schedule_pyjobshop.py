"""On makespan-only instances the `schedule` solver agrees with an independent model.

PyJobShop (a maintained scheduling library, its own CP-SAT model, stated in
benchmarks/pyjobshop_reference.py as a flexible job shop with setup times for travel)
answers the same instance. Without a workload cap and with no success floor, both
minimise the makespan: proven optima must be equal, and otherwise each one's best must
lie above the other's bound. PyJobShop's plan is checked against our rules as it comes
back.
"""

from __future__ import annotations

import pytest

from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.solvers.cpsat.search import solve_schedule
from benchmarks.pyjobshop_reference import MAX_SETUP_ARCS, setup_arcs, solve_with_pyjobshop
from benchmarks.timed_instances import construction_site
from benchmarks.unrelated_sites import unrelated_site

LIMIT_S = 20


@pytest.mark.parametrize(
    ("n_tasks", "n_robots", "seed"), [(8, 2, 1), (10, 3, 2), (12, 3, 3), (14, 3, 4)]
)
def test_makespan_optimum_agrees_with_pyjobshop(n_tasks: int, n_robots: int, seed: int) -> None:
    instance = construction_site(n_tasks, n_robots, seed=seed, light_pours=False)
    problem = Problem.build(
        instance, Mode.SUCCESS_FOCUSED, objective=Objective(ObjectiveKind.MAKESPAN)
    )
    ours = solve_schedule(problem, time_limit_s=LIMIT_S)
    assert check_schedule(problem, ours.schedule) == []
    theirs = solve_with_pyjobshop(instance, time_limit_s=LIMIT_S, workers=2)
    assert theirs.makespan is not None, f"PyJobShop found no plan: {theirs}"
    if ours.status == "optimal" and theirs.status == "Optimal":
        assert ours.makespan == pytest.approx(theirs.makespan)
    assert ours.makespan >= theirs.bound - 1e-6
    assert theirs.makespan >= ours.bound - 1e-6


def test_a_site_too_large_to_state_is_said_so_not_solved() -> None:
    # 1,000 x 20 of the second family: every robot may take every task, 20 million arcs
    # (stating them took all 24 GB of a machine here).
    instance = unrelated_site(1000, 20, seed=0)
    assert setup_arcs(instance) == 20 * 1001 * 1000 > MAX_SETUP_ARCS
    out = solve_with_pyjobshop(instance, time_limit_s=1.0)
    assert out.status == "not stated (20,020,000 setup arcs)" and out.makespan is None
    assert setup_arcs(unrelated_site(50, 3, seed=0)) == 3 * 51 * 50 < MAX_SETUP_ARCS
