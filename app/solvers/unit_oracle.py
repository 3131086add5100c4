"""Regret and guidance for the LTAA graph on an instance with team tasks
(docs/allocation.md#teams): `app.solvers.oracle.CompletionOracle` over task units.

The best completion from a state is the `optimal` solver's min-cost flow over units
(`app.solvers.unit_flow.place_units`) on the free tasks from the current one on, so the
guidance is the exact solver's choice and regrets telescope as they do for one robot per
task: a decision's regret is the success (mean over all tasks) it gives away against the
best completion before it.
"""

from __future__ import annotations

import bisect
from collections.abc import Sequence

from app.domain.decision import GuidedChoice
from app.domain.errors import InfeasibleCapError
from app.domain.problem import Problem
from app.domain.teams import team_problem, team_success
from app.solvers.unit_flow import Item, place_units
from app.solvers.units import Members, UnitView


class UnitOracle:
    """Exact values on the (possibly pinned) problem; a state is (task index, fleet loads)."""

    def __init__(self, problem: Problem) -> None:
        self._problem = problem
        self._view = UnitView.of(problem)
        self._items = [Item(i, self._view.units[i]) for i in range(len(self._view.tasks))]
        self._cache: dict[tuple[int, tuple[int, ...]], tuple[dict[int, Members], float] | None] = {}

    def _position(self, task_index: int) -> int:
        return bisect.bisect_left(self._problem.free_tasks, task_index)

    def _best(self, position: int, loads: Sequence[int]) -> tuple[dict[int, Members], float] | None:
        view = self._view
        key = (position, tuple(loads[r] for r in view.robots))
        if key not in self._cache:
            placed = place_units(view, self._items[position:], key[1], optimise=True)
            value = None
            if placed is not None:
                value = (placed, sum(self._gain(i, m) for i, m in placed.items()))
            self._cache[key] = value
            if len(self._cache) > 4096:  # runs move forward; old states are never asked again
                self._cache.pop(next(iter(self._cache)))
        return self._cache[key]

    def _gain(self, i: int, columns: Members) -> float:
        """S of free task i given to these columns (one for a single-robot task)."""
        t = self._view.tasks[i]
        robots = tuple(self._view.robots[c] for c in columns)
        return self._success(t, robots)

    def _success(self, t: int, members: Sequence[int]) -> float:
        inst = self._problem.instance
        if inst.units[t]:
            return team_success(inst.tasks[t], inst.robots, members)
        return float(inst.success[t, members[0]])

    def value(self, task_index: int, loads: Sequence[int]) -> float | None:
        """Largest sum of S over the free tasks from task_index on, reachable from `loads`."""
        position = self._position(task_index)
        if position >= len(self._items):
            return 0.0 if self._problem.cap.can_complete(loads, 0) else None
        best = self._best(position, loads)
        return None if best is None else best[1]

    def loss(
        self, task_index: int, loads: Sequence[int], members: int | Sequence[int]
    ) -> float | None:
        """Sum of S given away by this choice (None: not a valid or feasible one)."""
        chosen = (members,) if isinstance(members, int) else tuple(members)
        inst, problem = self._problem.instance, self._problem
        pinned = problem.pinned.get(task_index)
        if pinned is not None:
            return 0.0 if chosen == (pinned,) else None
        if any(r in problem.unavailable or not inst.eligible[task_index, r] for r in chosen):
            return None
        task = inst.tasks[task_index]
        if inst.units[task_index]:
            if team_problem(task, inst.robots, chosen) is not None:
                return None
        elif len(chosen) != 1:
            return None
        before = self.value(task_index, loads)
        after_loads = list(loads)
        for r in chosen:
            after_loads[r] += 1
        after = self.value(task_index + 1, after_loads)
        if before is None or after is None:
            return None
        return before - (self._success(task_index, chosen) + after)

    def regret(self, task_index: int, loads: Sequence[int], members: Sequence[int]) -> float:
        """Expected success (mean over all tasks) given away by this decision."""
        loss = self.loss(task_index, loads, members)
        if loss is None:
            raise InfeasibleCapError(
                f"task {task_index} to robots {list(members)} from loads {list(loads)} leaves "
                "no cap-respecting completion"
            )
        return max(0.0, loss) / self._problem.instance.n_tasks

    def guidance(self, task_index: int, loads: Sequence[int]) -> GuidedChoice | None:
        problem = self._problem
        n_robots = problem.instance.n_robots
        if task_index >= problem.instance.n_tasks:
            return None
        pinned = problem.pinned.get(task_index)
        if pinned is not None:
            pin_costs = tuple(0.0 if r == pinned else None for r in range(n_robots))
            return GuidedChoice(robot=pinned, costs=pin_costs)
        position = self._position(task_index)
        best = self._best(position, loads)
        if best is None:
            return None
        members = tuple(self._view.robots[c] for c in best[0][position])
        if problem.instance.units[task_index]:
            return GuidedChoice(robot=members[0], costs=(), team=members)
        costs = []
        for robot in range(n_robots):
            loss = self.loss(task_index, loads, robot)
            costs.append(None if loss is None else round(max(0.0, loss) * 100, 6))
        return GuidedChoice(robot=members[0], costs=tuple(costs))
