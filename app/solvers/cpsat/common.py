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

# CP-SAT's deterministic time per second of `time_limit_s`: measured on this machine's
# models (one worker), a unit of deterministic time took 2.8-3.7 s of CPU (Brandimarte
# Mk06, Mk10; 1,000 x 20 neighbourhoods). The budget is in these units, so the same request searches
# the same way on a quiet and on a loaded machine (docs/schedules.md#deterministic-search).
DET_PER_S = 0.35
# The wall-clock safety net: a call stops after this many times its time limit (plus a
# constant for building the models), whatever its deterministic budget says.
# Generous: on this shared machine (load 10-15 on 2 cores) a deterministic unit took up
# to 10x its quiet wall time, and a cut search is no longer the deterministic answer.
WALL_CAP_FACTOR = 10.0
WALL_CAP_EXTRA_S = 10.0


@dataclass
class Search:
    """One call's budget in deterministic time: every CP-SAT run takes what it is given of
    it, and `charge` books the Python work around the runs at a modelled, load-free cost.
    The wall clock only caps the call (`wall_cut` says when it did)."""

    time_limit_s: float
    workers: int
    seed: int
    started: float = field(default_factory=time.perf_counter)
    stages: list[dict[str, Any]] = field(default_factory=list)
    spent: float = 0.0  # deterministic units used so far
    wall_cut: bool = False
    # After each stage that improved: (the least budget, in deterministic units, whose run
    # reaches this point; units spent; wall seconds; best makespan; bound). A smaller
    # budget's answer is the last point it reaches (docs/schedules.md#anytime).
    trajectory: list[tuple[float, float, float, float, float]] = field(default_factory=list)
    needed: float = 0.0  # the least budget whose run has done everything done so far
    wall_cap_s: float | None = None  # default: WALL_CAP_FACTOR x time_limit_s + extra

    @property
    def budget(self) -> float:
        return self.time_limit_s * DET_PER_S

    def remaining(self) -> float:
        """Deterministic units left (0 once the wall-clock cap has cut the call)."""
        if self.wall_left() <= 0:
            self.wall_cut = True
            return 0.0
        return self.budget - self.spent

    def fits(self, units: float) -> bool:
        return units <= self.remaining() + 1e-9

    def charge(self, units: float) -> None:
        self.spent += units

    @property
    def cap(self) -> float:
        if self.wall_cap_s is not None:
            return self.wall_cap_s
        return WALL_CAP_FACTOR * self.time_limit_s + WALL_CAP_EXTRA_S

    def wall_left(self) -> float:
        return self.cap - (time.perf_counter() - self.started)

    def elapsed(self) -> float:
        return time.perf_counter() - self.started

    def solver(self, units: float) -> cp_model.CpSolver:
        """A CP-SAT solver that searches deterministically for `units` at most."""
        solver = cp_model.CpSolver()
        solver.parameters.max_deterministic_time = max(0.01, units)
        solver.parameters.max_time_in_seconds = max(0.05, self.wall_left())
        solver.parameters.num_workers = self.workers
        solver.parameters.random_seed = self.seed
        if self.workers > 1:
            # Parallel workers in deterministic batches: the same answer every run.
            solver.parameters.interleave_search = True
        return solver

    def book(self, solver: cp_model.CpSolver) -> None:
        self.spent += solver.deterministic_time
        if solver.wall_time >= solver.parameters.max_time_in_seconds - 0.01:
            self.wall_cut = True

    def run(
        self,
        model: cp_model.CpModel,
        name: str,
        units: float,
        *,
        disjunctive: bool = False,
        light_presolve: bool = False,
        fixed_search: bool = False,
    ) -> tuple[cp_model.CpSolver, str]:
        solver = self.solver(units)
        if fixed_search:
            # The model's own decision strategy first (then CP-SAT's default on the rest),
            # with the LP's cuts of linearization level 2: team_search.py says where.
            solver.parameters.search_branching = cp_model.FIXED_SEARCH
            solver.parameters.linearization_level = 2
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
        self.book(solver)
        found = status in ("OPTIMAL", "FEASIBLE")
        self.stages.append(
            {
                "stage": name,
                "status": status,
                "wall_s": round(solver.wall_time, 3),
                "deterministic_time": round(solver.deterministic_time, 3),
                "objective": solver.objective_value if found else None,
                "bound": solver.best_objective_bound,
            }
        )
        return solver, status

    def summary(self) -> dict[str, Any]:
        """What the answer reports about its budget: the deterministic units it had and
        used, the search's settings, and whether the wall-clock cap cut it."""
        return {
            "time_limit_s": self.time_limit_s,
            "deterministic_budget": round(self.budget, 3),
            "deterministic_used": round(self.spent, 3),
            "workers": self.workers,
            "seed": self.seed,
            "interleave_search": self.workers > 1,
            "wall_cap_s": self.cap,
            "wall_cut": self.wall_cut,
        }

    def need(self, units: float) -> None:
        """Book that a run reaches what follows only with a budget of `units` or more."""
        self.needed = max(self.needed, units)

    def mark(self, makespan: float, bound: float | None = None) -> None:
        """A point of the trajectory (bound None: the last one's)."""
        if bound is None:
            bound = self.trajectory[-1][4] if self.trajectory else 0.0
        point = (round(self.needed, 4), round(self.spent, 4), round(self.elapsed(), 3))
        self.trajectory.append((*point, makespan, bound))


# The modelled deterministic cost of building a CP-SAT model in Python, per variable and
# constraint (measured: ~4 microseconds each on a quiet core, booked as 4e-6 units).
BUILD_COST_PER_ITEM = 4e-6


def model_cost(model: cp_model.CpModel) -> float:
    proto = model.proto
    return BUILD_COST_PER_ITEM * (len(proto.variables) + len(proto.constraints))


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


def free_dispatch(
    problem: Problem, pairs: set[tuple[int, int]] | None, slowness: float = 0.0
) -> Schedule:
    """Earliest-finish dispatch with every allowed robot open to every task (one class per
    set of robots able, no quotas), each minute of slowness charged `slowness` minutes
    (`dispatch_schedule`): ValueError/DomainError when it cannot place a task."""
    tm = problem.instance.timing
    sets: dict[frozenset[int], int] = {}
    classes = []
    for t in range(tm.n_tasks):
        pin = problem.pinned.get(t)
        able = frozenset(
            [pin]
            if pin is not None
            else [
                r
                for r in tm.eligible_robots(t)
                if r not in problem.unavailable and (pairs is None or (t, r) in pairs)
            ]
        )
        classes.append(sets.setdefault(able, len(sets)))
    quotas = {(c, r): tm.n_tasks for able, c in sets.items() for r in able}
    return dispatch_schedule(problem, classes, quotas, slowness=slowness)


# A task's quickest robot at least this much quicker than its slowest: speeds that matter.
SPEED_SPREAD = 1.5


def speeds_decide(
    problem: Problem, weights: SuccessWeights, candidates: Sequence[Sequence[int]]
) -> bool:
    """Is the choice of robot the speeds' to make? True where, for every task, all robots
    it may take give the same expected success (the objective leaves the choice free, as
    on Brandimarte's shops and the second benchmark family), some task's quickest robot is
    `SPEED_SPREAD` times quicker than its slowest, and tasks lie in zones with travel
    between them. The large path then also runs the steps meant for unrelated robots
    (`large._dispatch_quick`, the LNS's `speed` and `zone` neighbourhoods); elsewhere it
    runs as it did before them."""
    tm = problem.instance.timing
    if not tm.has_travel:
        return False
    spread = False
    for t, robots in enumerate(candidates):
        if len({weights[t, r] for r in robots}) > 1:
            return False
        minutes = [tm.duration(t, r) for r in robots]
        spread = spread or (len(minutes) > 1 and max(minutes) >= SPEED_SPREAD * min(minutes))
    return spread


def makespan_floor(problem: Problem, pairs: set[tuple[int, int]] | None = None) -> float:
    """A lower bound on the makespan of any schedule that uses only `pairs` (default: every
    allowed pair): chains of shortest durations from the releases (and `not_before`), fixed
    tasks' ends, and the work spread over the robots."""
    tm = problem.instance.timing
    begin = [0.0] * tm.n_tasks  # lower bounds on the starts, for links from a start
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
        longest = max(tm.duration(t, r) for r in options)
        work += shortest
        robots.update(options)
        fixed = problem.pinned_starts.get(t)
        if fixed is not None:
            begin[t], finish[t] = fixed, fixed + shortest
            continue
        # docs/schedules.md#links: the longest duration bounds a start, the shortest an end
        begin[t] = max(tm.ready(t, longest, begin, finish), tm.release[t], problem.not_before)
        finish[t] = max(tm.ready(t, shortest, begin, finish) + shortest, begin[t] + shortest)
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
