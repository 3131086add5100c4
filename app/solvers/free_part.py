"""What a solver actually decides: the free tasks on the available robots.

Pins fix some tasks and unavailable robots take no new task (docs/living-plans.md#pins-in-allocate),
so every solver works on a smaller problem: the success rows of the free tasks, the columns of the
available robots, loads that start from the pins, and the same cap bounds. Robot order
among the available robots is the fleet's, so the robot-order tie-break carries over.
Without pins it is the whole problem: the same matrix, no copy.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, replace

import numpy as np

from app.domain.cap import WorkloadCap
from app.domain.completion import completable
from app.domain.problem import Problem


@dataclass(frozen=True)
class FreePart:
    problem: Problem
    success: np.ndarray  # (free tasks, available robots)
    cap: WorkloadCap  # the problem's bounds, over these columns only
    initial_loads: tuple[int, ...]  # per available robot: the pins on it

    @classmethod
    def of(cls, problem: Problem) -> FreePart:
        s = problem.instance.success
        if not problem.pinned and not problem.unavailable:
            return cls(problem, s, problem.cap, problem.initial_loads)
        rows = np.asarray(problem.free_tasks, dtype=np.int64)
        cols = np.asarray(problem.available, dtype=np.int64)
        sub = s[np.ix_(rows, cols)]
        sub.setflags(write=False)
        loads = tuple(problem.initial_loads[r] for r in problem.available)
        return cls(problem, sub, replace(problem.cap, unavailable=frozenset()), loads)

    @property
    def eligible(self) -> np.ndarray:
        """E[free task, available robot]; all true unless a timed task's duration map
        leaves robots out (docs/schedules.md#the-model)."""
        e = self.problem.instance.eligible
        if not self.problem.pinned and not self.problem.unavailable:
            return e
        rows = np.asarray(self.problem.free_tasks, dtype=np.int64)
        cols = np.asarray(self.problem.available, dtype=np.int64)
        return e[np.ix_(rows, cols)]

    def feasible_robots(self, t: int, loads: Sequence[int]) -> list[int]:
        """Columns that may take free task t from `loads` and keep the cap satisfiable; on an
        instance with eligibility restrictions (docs/allocation.md#teams) only eligible ones
        after which every later free task still gets an eligible robot."""
        robots = self.cap.feasible_robots(loads, self.n_tasks - t - 1)
        e = self.eligible
        if e.all():
            return robots
        lo, hi = self.cap.lower, self.cap.upper
        out = []
        for c in robots:
            after = list(loads)
            after[c] += 1
            if e[t, c] and completable(e[t + 1 :], after, lo, hi):
                out.append(c)
        return out

    @property
    def n_tasks(self) -> int:
        return int(self.success.shape[0])

    @property
    def n_robots(self) -> int:
        return int(self.success.shape[1])

    def assignment(self, choices: Sequence[int]) -> list[int]:
        """The full assignment (fleet robot per task) from one column per free task."""
        if not self.problem.pinned and not self.problem.unavailable:
            return [int(c) for c in choices]
        robots = self.problem.available
        return self.problem.complete([robots[c] for c in choices])
