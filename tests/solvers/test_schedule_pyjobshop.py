"""On makespan-only instances the `schedule` solver agrees with an independent model.

PyJobShop (a maintained scheduling library, its own CP-SAT model) states the problem as a
flexible job shop: a machine per robot, a mode per (task, robot that may take it), setup
times on each machine for travel between zones, releases as earliest starts, deadlines
as latest ends, shifts as machine breaks, precedence as end-before-start. A robot's start
zone is a zero-length origin task fixed at its shift start, on its machine only, whose
setup time to each task is the travel from the start zone. Without a workload cap and
with no success floor, both minimise the makespan: proven optima must be equal, and
otherwise each one's best must lie above the other's bound.
"""

from __future__ import annotations

import math

import pytest
from pyjobshop import Model

from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.solvers.cpsat.search import solve_schedule
from benchmarks.timed_instances import construction_site

LIMIT_S = 20


def pyjobshop_makespan(instance: Instance) -> tuple[float, float, bool]:
    """(best makespan, lower bound, proven optimal) from PyJobShop."""
    tm = instance.timing
    model = Model()
    machines = []
    for _, b in tm.shifts:
        breaks = [] if math.isinf(b) else [(int(b), int(b) + 10**6)]
        machines.append(model.add_machine(breaks=breaks))
    origins = []
    for r, (a, _) in enumerate(tm.shifts):
        origin = model.add_task(earliest_start=int(a), latest_start=int(a))
        model.add_mode(origin, machines[r], 0)
        origins.append(origin)
    tasks = []
    for t in range(tm.n_tasks):
        deadline = tm.deadline[t]
        task = model.add_task(
            earliest_start=int(tm.release[t]),
            latest_end=int(deadline) if math.isfinite(deadline) else 2**42,
        )
        tasks.append(task)
        for r in tm.eligible_robots(t):
            model.add_mode(task, machines[r], int(tm.duration(t, r)))
    for t, preds in enumerate(tm.predecessors):
        for p in preds:
            model.add_end_before_start(tasks[p], tasks[t])
    for r in range(tm.n_robots):
        mine = [t for t in range(tm.n_tasks) if tm.durations[t][r] is not None]
        for t in mine:
            model.add_setup_time(
                machines[r], origins[r], tasks[t], int(tm.travel_to_task(tm.robot_zone[r], t))
            )
            for u in mine:
                move = tm.travel(tm.task_zone[t], tm.task_zone[u])
                if u != t and move:
                    model.add_setup_time(machines[r], tasks[t], tasks[u], int(move))
    model.set_objective(weight_makespan=1)
    result = model.solve(time_limit=LIMIT_S, display=False, num_workers=2)
    return float(result.objective), float(result.lower_bound), result.status.value == "Optimal"


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
    theirs, their_bound, their_proof = pyjobshop_makespan(instance)
    if ours.status == "optimal" and their_proof:
        assert ours.makespan == pytest.approx(theirs)
    assert ours.makespan >= their_bound - 1e-6
    assert theirs >= ours.bound - 1e-6
