"""The best expected success still reachable from a partial allocation, exactly.

Used for per-decision regret (how much of the optimum a decision gave away) and for
optimizer guidance (the optimal completion's choice for the current task, and what each
alternative would cost). Values are sums of S over the remaining tasks, computed by the
same min-cost flow as the `optimal` solver, so regrets telescope: summed over a run they
equal optimal's expected success minus the run's.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence

import numpy as np

from app.domain.decision import GuidedChoice
from app.domain.errors import InfeasibleCapError
from app.domain.problem import Problem
from app.solvers.free_part import FreePart
from app.solvers.optimal import TaskClasses, class_allocation


class CompletionOracle:
    """Exact values on the (possibly pinned) problem.

    A state is (task_index, loads): `loads` has one entry per robot of the fleet and
    already holds every pin on an available robot (Problem.initial_loads) plus the free
    decisions made so far; unavailable robots' entries are ignored. Only the free tasks
    from `task_index` on are still to place, on available robots. A pinned task has one
    choice, its pin, which costs nothing.
    """

    def __init__(self, problem: Problem) -> None:
        self._problem = problem
        self._part = FreePart.of(problem)
        self._success = problem.instance.success
        # Classes once per run: each query is then a flow over classes, not over tasks.
        # With eligibility restrictions (docs/allocation.md#teams) classes also share their
        # eligibility row, and the flow has no arc to a robot a class may not go to.
        eligible = self._part.eligible
        self._eligible = None if eligible.all() else eligible
        self._classes = TaskClasses.of(self._part.success, self._eligible)
        self._allowed = None
        if self._eligible is not None:
            of_task = self._classes.of_task
            first = [int(np.argmax(of_task == c)) for c in range(len(self._classes.rows))]
            self._allowed = self._eligible[first]
        self._cache: dict[tuple[int, tuple[int, ...]], tuple[np.ndarray, float]] = {}

    def _position(self, task_index: int) -> int:
        """Index into the free tasks of the first free task at or after `task_index`."""
        if not self._problem.pinned:
            return min(task_index, self._part.n_tasks)
        return bisect.bisect_left(self._problem.free_tasks, task_index)

    def _free_loads(self, loads: Sequence[int]) -> tuple[int, ...]:
        if not self._problem.unavailable:
            return tuple(loads)
        return tuple(loads[r] for r in self._problem.available)

    def _best(self, position: int, loads: Sequence[int]) -> tuple[np.ndarray, float] | None:
        """(x[class, robot], sum of S) of an optimal completion from this state."""
        key = (position, self._free_loads(loads))
        if key not in self._cache:
            classes = self._classes
            try:
                x = class_allocation(
                    classes.rows, classes.counts(position), self._part.cap, key[1], self._allowed
                )
            except InfeasibleCapError:
                return None
            self._cache[key] = (x, float((x * classes.rows).sum()))
            if len(self._cache) > 4096:  # runs move forward; old states are never asked again
                self._cache.pop(next(iter(self._cache)))
        return self._cache[key]

    def value(self, task_index: int, loads: Sequence[int]) -> float | None:
        """Largest sum of S over the free tasks task_index.. reachable from `loads`
        within the cap."""
        position = self._position(task_index)
        if position >= self._part.n_tasks:
            return 0.0 if self._problem.cap.can_complete(loads, 0) else None
        best = self._best(position, loads)
        return None if best is None else best[1]

    def loss(self, task_index: int, loads: Sequence[int], robot: int) -> float | None:
        """Sum of S given away by giving task `task_index` to `robot` (None: infeasible)."""
        pinned = self._problem.pinned.get(task_index)
        if pinned is not None:
            return 0.0 if robot == pinned else None
        if (
            robot in self._problem.unavailable
            or not self._problem.instance.eligible[task_index, robot]
        ):
            return None
        before = self.value(task_index, loads)
        after_loads = list(loads)
        after_loads[robot] += 1
        after = self.value(task_index + 1, after_loads)
        if before is None or after is None:
            return None
        return before - (float(self._success[task_index, robot]) + after)

    def regret(self, task_index: int, loads: Sequence[int], robot: int) -> float:
        """Expected success (mean over all tasks, pins included) given away by this decision."""
        loss = self.loss(task_index, loads, robot)
        if loss is None:
            raise InfeasibleCapError(
                f"task {task_index} to robot {robot} from loads "
                f"{list(loads)} leaves no cap-respecting completion"
            )
        return loss / self._problem.instance.n_tasks

    def guidance(self, task_index: int, loads: Sequence[int]) -> GuidedChoice | None:
        n_robots = self._problem.instance.n_robots
        if task_index >= self._problem.instance.n_tasks:
            return None
        pinned = self._problem.pinned.get(task_index)
        if pinned is not None:
            return GuidedChoice(
                robot=pinned, costs=tuple(0.0 if r == pinned else None for r in range(n_robots))
            )
        position = self._position(task_index)
        best = self._best(position, loads)
        if best is None:
            return None
        # The current task takes the lowest-numbered robot its class uses (as optimal does).
        row = best[0][self._classes.of_task[position]]
        guided = self._problem.available[int(np.flatnonzero(row)[0])]
        costs = []
        for robot in range(n_robots):
            loss = self.loss(task_index, loads, robot)
            costs.append(None if loss is None else round(max(0.0, loss) * 100, 6))
        return GuidedChoice(robot=guided, costs=tuple(costs))
