"""Greedy: each task in turn to the highest-S robot that keeps the cap feasible."""

from __future__ import annotations

from typing import Any

import numpy as np

from app.domain.cap import CapTracker
from app.domain.problem import Problem
from app.solvers.base import Solution, Solver, SolverInfo
from app.solvers.free_part import FreePart
from app.solvers.unit_greedy import greedy_units
from app.solvers.units import UnitView, needs_units


class GreedySolver(Solver):
    info = SolverInfo(
        name="greedy",
        description="Task by task, the robot with the highest success whose choice keeps the "
        "workload cap satisfiable (ties: robot order).",
        exact=False,
        limits="any size within the request limits",
    )

    forms_teams = True

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        if needs_units(problem):  # teams or eligibility: only choices a completion admits
            return greedy_units(UnitView.of(problem))
        part = FreePart.of(problem)  # pinned tasks stay put; unavailable robots are not columns
        s = part.success
        tracker = CapTracker(part.cap, part.initial_loads)
        # Robots by descending S per task (stable sort keeps robot order among ties); on a
        # timed instance, robots a task's duration map leaves out rank last
        # (docs/schedules.md#the-model).
        eligible = part.eligible
        key = s if eligible.all() else np.where(eligible, s, -1.0)
        ranked = np.argsort(-key, axis=1, kind="stable").tolist()
        choices: list[int] = []
        for t in range(s.shape[0]):
            choice = next(i for i in ranked[t] if tracker.allows(i))
            tracker.assign(choice)
            choices.append(choice)
        return Solution(part.assignment(choices))
