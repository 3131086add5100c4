"""What the exact and the large-instance scheduling paths share.

The time budget and CP-SAT runs (`Search`), the expected success in integers
(`SuccessWeights`: the same scaled weights the exact allocation solvers compare, so
"equal ES" means the same thing everywhere), the feasible schedules found so far
(`Candidates`: each checked by the one feasibility function), the time-free optimum and
its schedules, and a lower bound on the makespan that holds for any schedule.
"""

from __future__ import annotations

import contextlib
import math
import time
from collections.abc import Callable, Sequence
from dataclasses import dataclass, field
from functools import reduce
from typing import Any

import numpy as np
from ortools.sat.python import cp_model

from app.domain.errors import DomainError
from app.domain.problem import Problem
from app.domain.scheduling.dispatch import dispatch_schedule, quotas_of
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.list_schedule import list_schedule, sequence_schedule
from app.domain.scheduling.schedule import Schedule
from app.solvers.free_part import FreePart
from app.solvers.optimal import best_completion
from app.solvers.tiebreak import integer_weights, weight_scale


@dataclass
class Search:
    """One call's budget: every CP-SAT run takes what is left of `time_limit_s`."""

    time_limit_s: float
    workers: int
    seed: int
    started: float = field(default_factory=time.perf_counter)
    stages: list[dict[str, Any]] = field(default_factory=list)

    def remaining(self) -> float:
        return self.time_limit_s - (time.perf_counter() - self.started)

    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def run(
        self,
        model: cp_model.CpModel,
        name: str,
        seconds: float,
        *,
        disjunctive: bool = False,
        light_presolve: bool = False,
    ) -> tuple[cp_model.CpSolver, str]:
        solver = cp_model.CpSolver()
        solver.parameters.max_time_in_seconds = max(0.05, seconds)
        solver.parameters.num_workers = self.workers
        solver.parameters.random_seed = self.seed
        if disjunctive:
            # Measured on the 36-task timed instance: with these two the bound closes in
            # seconds; without them it stalls ~5% below the optimum.
            solver.parameters.use_strong_propagation_in_disjunctive = True
            solver.parameters.use_objective_lb_search = True
        if light_presolve:
            # Measured at 1,000 x 20: probing alone took 10 s of a 15 s limit before any
            # search; one presolve pass without probing leaves the time to the search.
            solver.parameters.cp_model_probing_level = 0
            solver.parameters.max_presolve_iterations = 1
        status = solver.status_name(solver.solve(model))
        found = status in ("OPTIMAL", "FEASIBLE")
        self.stages.append(
            {
                "stage": name,
                "status": status,
                "wall_s": round(solver.wall_time, 3),
                "objective": solver.objective_value if found else None,
                "bound": solver.best_objective_bound,
            }
        )
        return solver, status


class SuccessWeights:
    """Integer expected success per (task, robot), divided by the common divisor (the
    paper's rates are multiples of 0.025: weights of a few dozen units)."""

    def __init__(self, problem: Problem) -> None:
        instance, cap = problem.instance, problem.cap
        scale = weight_scale(cap.n_tasks, cap.n_robots, instance.n_tasks)
        raw = integer_weights(instance.success, scale)
        divisor = reduce(math.gcd, (int(v) for v in np.unique(raw)), 0) or 1
        self.table = raw // divisor
        self.success_per_unit = divisor / scale
        self.n_tasks = instance.n_tasks

    def __getitem__(self, pair: tuple[int, int]) -> int:
        return int(self.table[pair])

    def of(self, robots: Sequence[int]) -> int:
        return int(self.table[np.arange(self.n_tasks), np.asarray(robots)].sum())

    def units(self, mean_success: float) -> int:
        """The smallest integer sum whose mean success reaches `mean_success`."""
        return math.ceil(mean_success * self.n_tasks / self.success_per_unit - 1e-6)

    def mean(self, units: float) -> float:
        return units * self.success_per_unit / self.n_tasks


class Candidates:
    """Feasible schedules found so far with their integer ES; `keep` filters them by the
    objective's ES condition once it is known."""

    def __init__(self, problem: Problem, weights: SuccessWeights) -> None:
        self.problem, self.weights = problem, weights
        self.found: list[tuple[int, Schedule]] = []
        self.condition: Callable[[int], bool] = lambda es: True

    def offer(self, schedule: Schedule) -> None:
        if not check_schedule(self.problem, schedule):
            self.found.append((self.weights.of(schedule.assignment), schedule))

    def offer_times(self, robots: Sequence[int], starts: Sequence[float]) -> None:
        """A solver's answer, re-timed: its per-robot orders at their earliest times."""
        sequences: list[list[int]] = [[] for _ in range(self.problem.instance.n_robots)]
        for t in sorted(range(len(robots)), key=lambda k: (starts[k], k)):
            sequences[robots[t]].append(t)
        self.offer_orders(sequences)

    def offer_orders(self, sequences: list[list[int]]) -> None:
        # A previous plan that no longer fits (e.g. its robot is gone) seeds nothing.
        with contextlib.suppress(ValueError, DomainError):
            self.offer(sequence_schedule(self.problem, sequences))

    def keep(self, condition: Callable[[int], bool]) -> None:
        self.condition = condition

    def best_es(self) -> int | None:
        return max((es for es, _ in self.found), default=None)

    def best(self) -> Schedule | None:
        kept = [(s.makespan, -es, i) for i, (es, s) in enumerate(self.found) if self.condition(es)]
        return None if not kept else self.found[min(kept)[2]][1]


def time_free_optimum(problem: Problem) -> list[int]:
    """The exact allocation optimum without time (min-cost flow, eligibility honoured):
    its expected success bounds every schedule's."""
    part = FreePart.of(problem)
    choices, _ = best_completion(part.success, part.cap, part.initial_loads, part.eligible)
    return part.assignment(choices)


def task_classes(problem: Problem) -> list[int]:
    """Tasks with the same success and eligibility rows are interchangeable for the
    expected success and the cap."""
    instance = problem.instance
    key = np.hstack([instance.success, ~instance.eligible])
    _, classes = np.unique(key, axis=0, return_inverse=True)
    return [int(c) for c in classes.reshape(-1)]


def assignment_schedules(problem: Problem, robots: list[int]) -> list[Schedule]:
    """An assignment timed two ways: as it is (the list scheduler), and with its per-class
    quotas dispatched by earliest finish (the same expected success and loads)."""
    groups = task_classes(problem)
    return [
        list_schedule(problem, robots),
        dispatch_schedule(problem, groups, quotas_of(robots, groups)),
    ]


def makespan_floor(problem: Problem, pairs: set[tuple[int, int]] | None = None) -> float:
    """A lower bound on the makespan of any schedule that uses only `pairs` (default: every
    allowed pair): chains of shortest durations from the releases (and `not_before`), fixed
    tasks' ends, and the work spread over the robots."""
    tm = problem.instance.timing
    finish = [0.0] * tm.n_tasks
    work, robots = 0.0, set()
    for t in tm.order:
        pin = problem.pinned.get(t)
        options = (
            [pin]
            if pin is not None
            else [
                r
                for r in tm.eligible_robots(t)
                if r not in problem.unavailable and (pairs is None or (t, r) in pairs)
            ]
        )
        shortest = min(tm.duration(t, r) for r in options)
        work += shortest
        robots.update(options)
        fixed = problem.pinned_starts.get(t)
        if fixed is not None:
            finish[t] = fixed + shortest
            continue
        ready = max((finish[p] for p in tm.predecessors[t]), default=0.0)
        finish[t] = max(ready, tm.release[t], problem.not_before) + shortest
    return max(max(finish, default=0.0), work / max(1, len(robots)))


def proved_none() -> DomainError:
    return DomainError(
        "tasks",
        "CP-SAT proved no schedule exists: no assignment and order meets every deadline, "
        "shift, precedence and the workload cap together; relax a deadline or a shift, or "
        "raise max_deviation",
        code="no_schedule",
    )


def none_found(time_limit_s: float, model: str) -> DomainError:
    return DomainError(
        "options.time_limit_s",
        f"no schedule that meets every deadline and shift was found within {time_limit_s:g} s "
        f"({model}); raise time_limit_s (at most 120), or relax a deadline or a shift",
        code="no_schedule_found",
    )
