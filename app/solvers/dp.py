"""Dynamic programme over (task index, load vector): the paper's exact DP baseline."""

from __future__ import annotations

import math
from typing import Any

from app.domain.errors import InfeasibleCapError, TooLargeError
from app.domain.problem import Problem
from app.solvers.base import Solution, Solver, SolverInfo
from app.solvers.free_part import FreePart
from app.solvers.tiebreak import better, deviation_units, integer_weights, weight_scale
from app.solvers.unit_search import dynamic_programme
from app.solvers.units import UnitView, needs_units

MAX_STATES = 400_000

Loads = tuple[int, ...]


def _plus_one(loads: Loads, i: int) -> Loads:
    return (*loads[:i], loads[i] + 1, *loads[i + 1 :])


def state_bound(n_tasks: int, n_robots: int) -> int:
    """(task index, load vector) states: C(t+r-1, r-1) load vectors with t tasks placed,
    summed over t. The DP and tabular Q-learning share this state space."""
    return math.comb(n_tasks + n_robots, n_robots)


class DynamicProgrammingSolver(Solver):
    info = SolverInfo(
        name="dp",
        description="Exact dynamic programme over (task index, load vector).",
        exact=True,
        limits=f"at most {MAX_STATES:,} (task, load-vector) states, about C(tasks+robots, robots)",
    )

    forms_teams = True

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        if needs_units(problem):  # teams or eligibility: each task's own choices
            view = UnitView.of(problem)
            teams, states = dynamic_programme(view, MAX_STATES)
            return view.solution(teams, {"states": states})
        # The free tasks on the available robots, loads starting from the pins.
        part = FreePart.of(problem)
        s, cap = part.success, part.cap
        n, r = s.shape
        bound = state_bound(n, r)
        if bound > MAX_STATES:
            raise TooLargeError(
                "tasks",
                f"dp would visit up to {bound:,} states for {n} {_free(problem)}tasks and {r} "
                f"{_available(problem)}robots, above its limit of {MAX_STATES:,}; use "
                "'optimal' for this size",
                code="too_large",
            )
        start: Loads = part.initial_loads
        # Forward: the load vectors from which a cap-respecting completion exists.
        layers: list[set[Loads]] = [{start} if cap.can_complete(start, n) else set()]
        for t in range(n):
            nxt: set[Loads] = set()
            for loads in layers[t]:
                for i in cap.feasible_robots(loads, n - t - 1):
                    nxt.add(_plus_one(loads, i))
            layers.append(nxt)
        # Backward: best (sum of integer weights, deviation) from each state, and the move.
        # Weights and deviation units are the ones every exact solver uses (tiebreak).
        w = integer_weights(s, weight_scale(cap.n_tasks, r, n)).tolist()
        value: dict[Loads, tuple[int, int]] = {
            loads: (0, deviation_units(loads, cap.n_tasks)) for loads in layers[n]
        }
        moves: list[dict[Loads, int]] = [{} for _ in range(n)]
        for t in range(n - 1, -1, -1):
            current: dict[Loads, tuple[int, int]] = {}
            for loads in layers[t]:
                best: tuple[int, int] | None = None
                for i in range(r):
                    child = _plus_one(loads, i)
                    if child not in value:
                        continue
                    v, d = value[child]
                    v += w[t][i]
                    if best is None or better(v, d, *best):
                        best, moves[t][loads] = (v, d), i
                if best is not None:
                    current[loads] = best
            value = current
        if start not in value:  # Problem.build refuses such caps; a direct caller may not
            cap.ensure_feasible()
            raise InfeasibleCapError("no completion of the free tasks fits the cap from the pins")
        choices: list[int] = []
        loads = start
        for t in range(n):
            i = moves[t][loads]
            choices.append(i)
            loads = _plus_one(loads, i)
        return Solution(part.assignment(choices), details={"states": sum(len(x) for x in layers)})


def _free(problem: Problem) -> str:
    return "free " if problem.pinned else ""


def _available(problem: Problem) -> str:
    return "available " if problem.unavailable else ""
