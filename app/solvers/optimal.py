"""Exact optimum at any size: the capped problem is a transportation problem.

Tasks with identical success rows are interchangeable, so they are grouped into
classes; flow goes class -> robot -> sink, and each robot's lower/upper load bounds
become node demand plus arc capacity. OR-Tools' min-cost flow returns an integral
optimum. Costs are integers: S scaled to an integer (1e-9 resolution on small
instances), multiplied by a factor larger than any deviation difference, plus the
deviation term R*|L - W| — so one solve gives "max success, then least deviation".

On a timed instance a robot that a task's duration map omits cannot take it
(docs/schedules.md#the-model): `eligible` then removes those arcs, and tasks group by success row
and eligibility row; robots' `skills` (docs/allocation.md#teams) remove arcs the same way.
Without such pairs nothing changes. An instance with team tasks is solved by the flow over
task units of `app.solvers.unit_flow` instead (each robot at most once per task).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from typing import Any

import numpy as np
from ortools.graph.python import min_cost_flow

from app.domain.cap import WorkloadCap
from app.domain.errors import InfeasibleCapError
from app.domain.problem import Problem
from app.solvers.base import Solution, Solver, SolverInfo
from app.solvers.free_part import FreePart
from app.solvers.tiebreak import deviation_arcs as _deviation_arcs
from app.solvers.tiebreak import deviation_factor, integer_weights, weight_scale
from app.solvers.unit_flow import best_units
from app.solvers.units import UnitView


@dataclass(frozen=True)
class TaskClasses:
    """Tasks with identical success rows are interchangeable: one flow node per class."""

    rows: np.ndarray  # (classes, robots) success rows, in first-appearance order
    of_task: np.ndarray  # class index of each task

    @classmethod
    def of(cls, success: np.ndarray, eligible: np.ndarray | None = None) -> TaskClasses:
        key = success if eligible is None else np.hstack([success, ~eligible])
        _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
        order = np.argsort(first)  # first-appearance order, for a stable tie-break
        rank = np.empty_like(order)
        rank[order] = np.arange(order.size)
        return cls(rows=success[first[order]], of_task=rank[inverse.reshape(-1)])

    def counts(self, start: int = 0) -> np.ndarray:
        return np.bincount(self.of_task[start:], minlength=len(self.rows))


def class_allocation(
    rows: np.ndarray,
    counts: np.ndarray,
    cap: WorkloadCap,
    initial_loads: Sequence[int],
    allowed: np.ndarray | None = None,
) -> np.ndarray:
    """x[c, r]: how many tasks of class c robot r takes in an optimal completion.

    The columns of `rows` are the robots in the cap's balance (a FreePart's), so `cap` has
    no unavailable robots and its W is n_tasks / (the number of columns).
    """
    n_classes, r = rows.shape
    if cap.unavailable or r != cap.n_robots:
        raise ValueError(
            f"class_allocation takes the {cap.n_robots} robots in the balance as columns, "
            f"got {r} (unavailable: {sorted(cap.unavailable)}); reduce with FreePart first"
        )
    m, n = int(counts.sum()), cap.n_tasks
    init = list(initial_loads)
    lo, hi = cap.lower, cap.upper
    need = [max(0, lo - x) for x in init]
    room = [hi - x for x in init]
    if min(room) < 0 or sum(need) > m or sum(room) < m:
        raise InfeasibleCapError(
            f"no completion of the remaining {m} tasks keeps every robot within "
            f"[{lo}, {hi}] tasks from loads {init}"
        )
    if m == 0:
        return np.zeros((n_classes, r), dtype=np.int64)
    factor = deviation_factor(n, r)
    weight = integer_weights(rows, weight_scale(n, r, m))

    robot0, sink = n_classes, n_classes + r
    tails, heads, caps, costs = [], [], [], []
    for c in range(n_classes):
        for i in range(r):
            if allowed is not None and not allowed[c, i]:
                continue  # zero capacity: the robot cannot take this class
            tails.append(c)
            heads.append(robot0 + i)
            caps.append(int(counts[c]))
            costs.append(-int(weight[c, i]) * factor)
    for i in range(r):
        for capacity, cost in _deviation_arcs(init[i] + need[i], hi, r, n):
            tails.append(robot0 + i)
            heads.append(sink)
            caps.append(capacity)
            costs.append(cost)

    flow = min_cost_flow.SimpleMinCostFlow()
    arcs = flow.add_arcs_with_capacity_and_unit_cost(
        np.array(tails), np.array(heads), np.array(caps), np.array(costs)
    )
    supplies = [int(x) for x in counts] + [-x for x in need] + [-(m - sum(need))]
    flow.set_nodes_supplies(np.arange(n_classes + r + 1), np.array(supplies))
    status = flow.solve()
    if status != flow.OPTIMAL:
        raise InfeasibleCapError(
            f"the min-cost flow found no allocation within [{lo}, {hi}] tasks per robot "
            f"(solver status {status})"
        )
    if allowed is None:
        return np.asarray(flow.flows(arcs[: n_classes * r])).reshape(n_classes, r)
    x = np.zeros((n_classes, r), dtype=np.int64)
    x[allowed] = flow.flows(arcs[: int(allowed.sum())])
    return x


def best_completion(
    success: np.ndarray,
    cap: WorkloadCap,
    initial_loads: Sequence[int] | None = None,
    eligible: np.ndarray | None = None,
) -> tuple[list[int], float]:
    """Optimal robots for the rows of `success`, given loads already placed.

    Returns (assignment, sum of S over these rows). `cap` is the whole run's cap, so its
    target and bounds refer to the final loads (initial + new). `eligible` (same shape,
    optional) marks the pairs allowed; None or all true allows every pair.
    """
    if eligible is not None and eligible.all():
        eligible = None
    m, r = success.shape
    init = list(initial_loads) if initial_loads is not None else [0] * r
    if m == 0:
        class_allocation(np.zeros((0, r)), np.zeros(0, dtype=np.int64), cap, init)
        return [], 0.0
    classes = TaskClasses.of(success, eligible)
    allowed = None
    if eligible is not None:
        first = [int(np.argmax(classes.of_task == c)) for c in range(len(classes.rows))]
        allowed = eligible[first]
    x = class_allocation(classes.rows, classes.counts(), cap, init, allowed)
    # Within a class, earlier tasks get lower-numbered robots: the robot-order tie-break.
    queues = [[i for i in range(r) for _ in range(int(x[c, i]))] for c in range(len(x))]
    cursor = [0] * len(x)
    assignment: list[int] = []
    for c in classes.of_task:
        assignment.append(queues[c][cursor[c]])
        cursor[c] += 1
    total = float(success[np.arange(m), assignment].sum())
    return assignment, total


class OptimalSolver(Solver):
    info = SolverInfo(
        name="optimal",
        description="Exact optimum at any size: capped transportation problem solved by "
        "OR-Tools min-cost flow (max expected success, then least deviation).",
        exact=True,
        limits="any size within the request limits",
    )

    forms_teams = True

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        if problem.instance.has_teams:  # docs/allocation.md#teams: the flow over task units
            view = UnitView.of(problem)
            return view.solution(best_units(view), {"model": "min-cost flow over task units"})
        part = FreePart.of(problem)  # the free tasks on the available robots, from the pins
        choices, _ = best_completion(part.success, part.cap, part.initial_loads, part.eligible)
        return Solution(part.assignment(choices))
