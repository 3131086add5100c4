"""One solve per (solver, scenario, mode, cap, seed, options) for the whole bench process.

Several sections read the same allocations (the learners' seeds feed the solver table,
the learner figures and the methods comparison); training DQN twice would double the
bench's dominant cost, so every section asks here.
"""

from __future__ import annotations

import json
import time
from dataclasses import dataclass
from functools import cache
from typing import Any

from app.domain.catalog import scenario
from app.domain.metrics import Metrics, compute_metrics
from app.domain.modes import Mode
from app.domain.problem import Problem
from app.solvers.registry import get_solver

# Common random numbers: every allocation is simulated with the same seed, so differences
# between methods are not simulation noise.
SIMULATION_SEED = 0
SIMULATION_TRIALS = 1_000


@dataclass(frozen=True)
class Solved:
    solver: str
    scenario: str
    mode: str
    max_deviation: float | None  # the cap actually applied
    seed: int
    assignment: tuple[int, ...]
    metrics: Metrics
    seconds: float  # wall time of the one solve() call (training included for learners)
    details: dict[str, Any]


def problem_for(scenario_name: str, mode: str, max_deviation: float | None = None) -> Problem:
    return Problem.build(scenario(scenario_name).instance, Mode(mode), max_deviation)


def solved(
    solver: str,
    scenario_name: str = "baseline",
    mode: str = "balanced",
    *,
    seed: int = 0,
    max_deviation: float | None = None,
    options: dict[str, Any] | None = None,
) -> Solved:
    """The cached solve; options are keyed by their JSON text so dicts can be passed."""
    return _solved(
        solver, scenario_name, mode, seed, max_deviation, json.dumps(options or {}, sort_keys=True)
    )


@cache
def _solved(
    solver: str,
    scenario_name: str,
    mode: str,
    seed: int,
    max_deviation: float | None,
    options_json: str,
) -> Solved:
    problem = problem_for(scenario_name, mode, max_deviation)
    start = time.perf_counter()
    solution = get_solver(solver).solve(problem, seed=seed, options=json.loads(options_json))
    seconds = time.perf_counter() - start
    metrics = compute_metrics(
        problem.instance, solution.assignment, seed=SIMULATION_SEED, trials=SIMULATION_TRIALS
    )
    return Solved(
        solver,
        scenario_name,
        mode,
        problem.cap.max_deviation,
        seed,
        tuple(solution.assignment),
        metrics,
        seconds,
        dict(solution.details),
    )


GUIDED = {"guidance": "optimizer"}
