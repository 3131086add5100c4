"""Greedy: each task in turn to the highest-S robot that keeps the cap feasible."""

from __future__ import annotations

from typing import Any

from app.domain.problem import Problem
from app.solvers.base import Solution, Solver, SolverInfo


class GreedySolver(Solver):
    info = SolverInfo(
        name="greedy",
        description="Task by task, the robot with the highest success whose choice keeps the "
        "workload cap satisfiable (ties: robot order).",
        exact=False,
        limits="any size within the request limits",
    )

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        s, cap = problem.instance.success, problem.cap
        n, r = s.shape
        loads = [0] * r
        assignment: list[int] = []
        for t in range(n):
            feasible = cap.feasible_robots(loads, n - t - 1)
            choice = max(feasible, key=lambda i: (s[t, i], -i))
            loads[choice] += 1
            assignment.append(choice)
        return Solution(assignment)
