"""An independent model of a site (docs/schedules.md#an-outside-reference): PyJobShop.

PyJobShop, a maintained scheduling library with its own CP-SAT model, states the problem as
a flexible job shop: a machine per robot, a mode per (task, robot that may take it), setup
times on each machine for travel between zones, releases as earliest starts, deadlines as
latest ends, a shift's end as a machine break, precedence as end-before-start. A robot's
start zone is a zero-length origin task fixed at its shift start on its machine only,
whose setup time to each task is the travel from the start zone. It has no workload cap
and no success floor, so it answers the makespan-only problem (`Problem.build(...,
uncapped=True)`, the second family's and Brandimarte's) and nothing else; team tasks are
outside it.

Its answer comes back as our `Schedule` (one robot and start per task) and is checked by
`check_schedule` against the same rules as ours: a reference that broke a rule would
prove nothing.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass

from pyjobshop import Model
from pyjobshop.solvers.ortools import CPModel

from app.domain.models import Instance
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.schedule import build_schedule

# A break after the shift that no plan reaches: the machine is simply closed from then on.
_CLOSED = 10**9
_NO_DEADLINE = 2**42
# PyJobShop states travel as a setup time per ordered pair of tasks a robot may take: past
# this many arcs the model is not stated. Measured: 1,000 x 20 x 4 zones holds 20 million
# (every robot may take every task) and stating it took all 24 GB of this machine (the
# process was killed for memory); 600 x 12 holds 4.3 million.
MAX_SETUP_ARCS = 5_000_000


@dataclass(frozen=True)
class Reference:
    """What PyJobShop answered: its status ("Optimal", "Feasible", "Infeasible" or
    "Time-limit" with no plan), its makespan (None without a plan), its bound, the seconds
    spent stating the model (Python) and solving it (CP-SAT's wall time)."""

    status: str
    makespan: float | None
    bound: float
    build_s: float
    wall_s: float


def pyjobshop_model(instance: Instance) -> Model:
    """The PyJobShop model of `instance`: machine r is robot r, task r the robot's origin,
    task n_robots + t the site's task t."""
    tm = instance.timing
    if any(len(units) > 1 for units in instance.units):
        raise ValueError("the PyJobShop reference models one robot per task (no teams)")
    model = Model()
    machines = []
    for _, end in tm.shifts:
        breaks = [] if math.isinf(end) else [(int(end), int(end) + _CLOSED)]
        machines.append(model.add_machine(breaks=breaks))
    origins = []
    for r, (start, _) in enumerate(tm.shifts):
        origin = model.add_task(earliest_start=int(start), latest_start=int(start))
        model.add_mode(origin, machines[r], 0)
        origins.append(origin)
    tasks = []
    for t in range(tm.n_tasks):
        deadline = tm.deadline[t]
        task = model.add_task(
            earliest_start=int(tm.release[t]),
            latest_end=int(deadline) if math.isfinite(deadline) else _NO_DEADLINE,
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
            first = tm.travel_to_task(tm.robot_zone[r], t)
            if first:
                model.add_setup_time(machines[r], origins[r], tasks[t], int(first))
            for u in mine:
                move = tm.travel(tm.task_zone[t], tm.task_zone[u])
                if u != t and move:
                    model.add_setup_time(machines[r], tasks[t], tasks[u], int(move))
    model.set_objective(weight_makespan=1)
    return model


def setup_arcs(instance: Instance) -> int:
    """How many setup-time arcs `pyjobshop_model` would state (at most: pairs in one zone
    need none): per robot, its origin and the tasks it may take, every ordered pair."""
    tm = instance.timing
    mine = [
        sum(1 for t in range(tm.n_tasks) if tm.durations[t][r] is not None)
        for r in range(tm.n_robots)
    ]
    return sum((k + 1) * k for k in mine)


def solve_with_pyjobshop(
    instance: Instance, *, time_limit_s: float, workers: int = 1, seed: int = 0
) -> Reference:
    """Solve `instance`'s makespan-only problem with PyJobShop's CP-SAT model in
    `time_limit_s` of solver wall time (stating the model is timed apart). Raises if the
    plan it returns breaks one of our rules. Past `MAX_SETUP_ARCS` nothing is stated or
    solved: the status says so."""
    arcs = setup_arcs(instance)
    if arcs > MAX_SETUP_ARCS:
        return Reference(f"not stated ({arcs:,} setup arcs)", None, 0.0, 0.0, 0.0)
    began = time.perf_counter()
    cp = CPModel(pyjobshop_model(instance).data())
    built = time.perf_counter() - began
    result = cp.solve(time_limit_s, False, workers, None, random_seed=seed)
    status = result.status.value
    if not math.isfinite(result.objective):
        return Reference(status, None, float(result.lower_bound), built, result.runtime)
    tm = instance.timing
    placed = result.best.tasks[tm.n_robots :]
    robots = [s.resources[0] for s in placed]
    starts = [float(s.start) for s in placed]
    problem = Problem.build(instance, Mode.BALANCED, uncapped=True)
    schedule = build_schedule(problem, robots, starts)
    broken = check_schedule(problem, schedule)
    if broken:
        raise AssertionError(f"PyJobShop's plan breaks {len(broken)} rules: {broken[:3]}")
    return Reference(
        status, schedule.makespan, float(result.lower_bound), built, float(result.runtime)
    )
