"""Brute force: score every possible assignment. Exact; only for small instances."""

from __future__ import annotations

from typing import Any

import numpy as np

from app.domain.errors import InfeasibleCapError, TooLargeError
from app.domain.problem import Problem
from app.solvers.base import Solution, Solver, SolverInfo
from app.solvers.free_part import FreePart
from app.solvers.tiebreak import integer_weights, weight_scale
from app.solvers.unit_search import enumerate_all
from app.solvers.units import UnitView, needs_units

MAX_ASSIGNMENTS = 3**12


class BruteForceSolver(Solver):
    info = SolverInfo(
        name="brute_force",
        description="Enumerates every assignment and keeps the best that respects the cap.",
        exact=True,
        limits=f"robots^tasks <= 3^12 = {MAX_ASSIGNMENTS:,} assignments",
    )

    forms_teams = True

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        if needs_units(problem):  # teams or eligibility: each task's own choices
            view = UnitView.of(problem)
            choices, count = enumerate_all(view, MAX_ASSIGNMENTS, f"3^12 = {MAX_ASSIGNMENTS:,}")
            return view.solution(choices, {"enumerated": count})
        # Only the free tasks on the available robots are enumerated; pins are fixed.
        part = FreePart.of(problem)
        s, cap = part.success, part.cap
        n, r = s.shape
        count = r**n
        if count > MAX_ASSIGNMENTS:
            space = (
                "free tasks on available robots" if problem.pinned or problem.unavailable else ""
            )
            raise TooLargeError(
                "tasks",
                f"brute_force would enumerate {r}^{n} = {count:,} assignments"
                f"{f' ({space})' if space else ''}, above its limit of 3^12 = "
                f"{MAX_ASSIGNMENTS:,}; use 'dp' or 'optimal' for this size",
                code="too_large",
            )
        # Row k is assignment number k in lexicographic order (task 0 most significant),
        # so the first best row is also the robot-order tie-break.
        codes = np.arange(count, dtype=np.int64)
        powers = r ** np.arange(n - 1, -1, -1, dtype=np.int64)
        choices = (codes[:, None] // powers[None, :]) % r
        w = integer_weights(s, weight_scale(cap.n_tasks, r, n))
        values = w[np.arange(n)[None, :], choices].sum(axis=1)
        start = np.asarray(part.initial_loads, dtype=np.int64)
        loads = start[None, :] + np.stack([(choices == i).sum(axis=1) for i in range(r)], axis=1)
        ok = ((loads >= cap.lower) & (loads <= cap.upper)).all(axis=1)
        if not ok.any():  # Problem.build refuses such caps; a direct caller may not
            cap.ensure_feasible()
            raise InfeasibleCapError("no completion of the free tasks fits the cap from the pins")
        dev = np.abs(r * loads - cap.n_tasks).sum(axis=1)
        top = values[ok].max()
        tied = ok & (values == top)
        best_dev = dev[tied].min()
        winner = int(np.flatnonzero(tied & (dev == best_dev))[0])
        return Solution(
            part.assignment([int(c) for c in choices[winner]]), details={"enumerated": count}
        )
