"""Solving a timed problem with CP-SAT: which model runs, in which stages, what is proven.

Objectives (docs/schedules.md#schedulers), lexicographic by construction (two solves, not a weighted
sum):
- `success_then_makespan`: stage 1 maximises expected success (ES) under the cap; stage 2
  holds ES at stage 1's value (an equality constraint) and minimises the makespan. Stage 1
  is skipped when the time-free allocation optimum (min-cost flow: its ES bounds every
  schedule's) has a feasible schedule already: that ES is then proven, and stage 2 keeps
  only the (task, robot) pairs that some ES-optimal allocation uses (`success_pairs`).
- `makespan`: one solve, ES >= `min_expected_success` as a constraint.

Paths: up to `EXACT_LIMIT` (robots x tasks^2), the exact model (`schedule_model`);
past it the large-instance path (`large_schedule`), which never claims optimality.
Every answer is re-timed (earliest times for its per-robot orders, never later than
CP-SAT's) and must pass `check_schedule`. `status` is "optimal" only when CP-SAT proved the
makespan stage OPTIMAL, ES is proven, and time values are whole at the model's scale.
"""

from __future__ import annotations

from app.domain.errors import DomainError
from app.domain.objective import ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.schedule import EPS, Schedule
from app.solvers.cpsat.common import (
    Candidates,
    Search,
    SuccessWeights,
    assignment_schedules,
    makespan_floor,
    none_found,
    proved_none,
    time_free_optimum,
)
from app.solvers.cpsat.large import solve_large
from app.solvers.cpsat.model import ScheduleModel, Travel
from app.solvers.cpsat.outcome import ScheduleOutcome, Setup, outcome
from app.solvers.cpsat.success_pairs import success_optimal_pairs
from app.solvers.cpsat.time_scale import TimeScale

# robots x tasks^2 up to which the exact model runs (36 tasks x 3 robots: 3,888; 100 x 4:
# 40,000). Past it the pairwise travel literals alone run into the millions at 1,000 x 20,
# and (measured) a full model of 200 x 20 finds nothing better than the hint in 10 s.
EXACT_LIMIT = 40_000

EXACT_MODEL = "exact: no-overlap per robot + pairwise travel between zones"
EXACT_MODEL_NO_TRAVEL = "exact: no-overlap per robot (no travel between zones)"


def solve_schedule(
    problem: Problem,
    *,
    time_limit_s: float = 10.0,
    workers: int = 2,
    hint: Schedule | None = None,
    seed: int = 0,
) -> ScheduleOutcome:
    """The best schedule found within `time_limit_s`, with what is proven about it.

    `problem` may carry pins (with fixed starts), unavailable robots and `not_before`: the
    remaining tasks of a living plan. `hint` is a previous plan; it seeds the search and is
    kept if nothing better is found and it is still feasible. DomainError when CP-SAT
    proves no schedule exists, or none is found in time."""
    setup = _setup(problem, Search(time_limit_s, workers, seed), hint)
    tm = problem.instance.timing
    if tm.n_robots * tm.n_tasks**2 > EXACT_LIMIT:
        return solve_large(setup)
    return _solve_exact(setup, hint)


def _setup(problem: Problem, search: Search, hint: Schedule | None) -> Setup:
    weights = SuccessWeights(problem)
    flow = time_free_optimum(problem)
    feasible = Candidates(problem, weights)
    for schedule in assignment_schedules(problem, flow):
        feasible.offer(schedule)
    if hint is not None:
        feasible.offer_orders(hint.sequences(problem.instance.n_robots))
    es_bound = weights.of(flow)
    setup = Setup(
        problem, search, TimeScale.of(problem), weights, feasible, es_bound, None, None, None
    )
    objective = problem.objective
    if objective.kind is ObjectiveKind.MAKESPAN:
        floor = weights.units(objective.min_expected_success)
        if es_bound < floor:
            raise DomainError(
                "min_expected_success",
                f"no allocation under the cap reaches an expected success of "
                f"{objective.min_expected_success:g}; the best is {weights.mean(es_bound):.4f}",
                code="no_schedule",
            )
        setup.es_floor = floor
        feasible.keep(lambda es: es >= floor)
    elif feasible.best_es() == es_bound:
        setup.es_target = es_bound  # proven: nothing beats the time-free optimum
        setup.pairs = success_optimal_pairs(problem)
    return setup


def _solve_exact(setup: Setup, hint: Schedule | None) -> ScheduleOutcome:
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    travel = Travel.PAIRS if problem.instance.timing.has_travel else Travel.NONE
    name = EXACT_MODEL if travel is Travel.PAIRS else EXACT_MODEL_NO_TRAVEL
    model = ScheduleModel(problem, setup.scale, travel, setup.weights, setup.pairs)
    es_proven = True
    if setup.es_floor is not None:
        model.model.add(model.es >= setup.es_floor)
    else:
        if setup.es_target is None:
            setup.es_target, es_proven = _stage_success(setup, model, hint)
        target = setup.es_target
        model.model.add(model.es == target)
        feasible.keep(lambda es: es == target)
    model.model.minimize(model.makespan)
    seed_plan = feasible.best() or hint
    if seed_plan is not None:
        model.hint(seed_plan.assignment, [s.start for s in seed_plan.slots])
    solver, status = search.run(model.model, "makespan", search.remaining(), disjunctive=True)
    if status == "INFEASIBLE":
        raise proved_none()
    if status in ("OPTIMAL", "FEASIBLE"):
        feasible.offer_times(*model.read(solver))
    best = feasible.best()
    if best is None:
        raise none_found(search.time_limit_s, name)
    scale = setup.scale
    proven = (
        scale.exact
        and status == "OPTIMAL"
        and es_proven
        and best.makespan <= scale.minutes(solver.objective_value) + EPS
    )
    solver_bound = scale.minutes(solver.best_objective_bound) if scale.exact else 0.0
    bound = (
        best.makespan
        if proven
        else min(best.makespan, max(makespan_floor(problem, setup.pairs), solver_bound))
    )
    return outcome(setup, best, "optimal" if proven else "feasible", name, bound)


def _stage_success(setup: Setup, model: ScheduleModel, hint: Schedule | None) -> tuple[int, bool]:
    """Stage 1: the most ES a schedule reaches, and whether that is proven."""
    search, feasible = setup.search, setup.feasible
    model.model.add(model.es <= setup.es_bound)
    model.model.maximize(model.es)
    seed_plan = feasible.best() or hint
    if seed_plan is not None:
        model.hint(seed_plan.assignment, [s.start for s in seed_plan.slots])
    solver, status = search.run(
        model.model, "expected success", search.remaining() / 2, disjunctive=True
    )
    if status == "INFEASIBLE":
        raise proved_none()
    if status in ("OPTIMAL", "FEASIBLE"):
        feasible.offer_times(*model.read(solver))
    reached = feasible.best_es()
    if reached is None:
        raise none_found(search.time_limit_s / 2, "stage 1, expected success")
    proven = reached == setup.es_bound or (status == "OPTIMAL" and setup.scale.exact)
    return reached, proven
