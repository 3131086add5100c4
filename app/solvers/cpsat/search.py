"""Solving a timed problem with CP-SAT: which model runs, in which stages, what is proven.

Objectives (docs/schedules.md#schedulers), lexicographic by construction (two solves,
not a weighted sum):
- `success_then_makespan`: stage 1 maximises expected success (ES) under the cap; stage 2
  holds ES at stage 1's value (an equality constraint) and minimises the makespan. Stage 1
  is skipped when the time-free allocation optimum (min-cost flow: its ES bounds every
  schedule's) has a feasible schedule already: that ES is then proven, and stage 2 keeps
  only the (task, robot) pairs that some ES-optimal allocation uses (`success_pairs`).
- `makespan`: one solve, ES >= `min_expected_success` as a constraint.

Paths: while the exact model's real size (`model_size`: presence literals, and travel
order literals only where travel applies) is within `EXACT_LIMIT` and `EXACT_INTERVALS`,
the exact model (`model.py`) in deterministic chunks; past it the large-instance path
(`large.py`), which never claims optimality. The budget is deterministic
(docs/schedules.md#deterministic-search) and a larger one continues a smaller one's
search (docs/schedules.md#anytime).
Every answer is re-timed (earliest times for its per-robot orders, never later than
CP-SAT's) and must pass `check_schedule`. `status` is "optimal" only when CP-SAT proved the
makespan stage OPTIMAL, ES is proven, and time values are whole at the model's scale.
"""

from __future__ import annotations

import contextlib

from app.domain.errors import DomainError
from app.domain.objective import ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.schedule import Schedule
from app.solvers.cpsat.bounds import best_bound, bound_floors
from app.solvers.cpsat.common import (
    DET_PER_S,
    Candidates,
    Search,
    SuccessWeights,
    assignment_schedules,
    free_dispatch,
    model_cost,
    none_found,
    proved_none,
    time_free_optimum,
)
from app.solvers.cpsat.large import _candidates as large_candidates
from app.solvers.cpsat.large import solve_large
from app.solvers.cpsat.lns import improve
from app.solvers.cpsat.model import ScheduleModel, Travel
from app.solvers.cpsat.outcome import ScheduleOutcome, Setup, outcome
from app.solvers.cpsat.success_pairs import success_optimal_pairs
from app.solvers.cpsat.team_search import solve_team_schedule
from app.solvers.cpsat.time_scale import TimeScale

# The exact model runs while it has at most this many literals: a presence literal per
# (task, robot that may take it), and, where travel applies, an order literal per two
# tasks in different zones that one robot may both take (36 x 3 with travel: ~2,000;
# 100 x 4: ~20,000). Past it the pairwise travel literals alone run into the millions at
# 1,000 x 20, and (measured) a full model of 200 x 20 finds nothing better than the hint
# in 10 s. Without travel the model is one optional interval per pair and a NoOverlap per
# robot: Brandimarte's Mk10 (240 operations, 15 machines) has under 1,000.
EXACT_LIMIT = 20_000
# ... and at most this many presence literals (intervals): measured, a no-travel model of
# 1,000 x 20 (20,000 intervals) found no schedule in 60 s.
EXACT_INTERVALS = 5_000
# Where the exact model's search restarts from its best plan and bound, in seconds of
# `time_limit_s` (deterministic), each chunk as long as all before it. Measured: restarts
# cost proofs (the 36-task timed optimum, proven in 0.28 units by one run from the list
# schedule, was not in six short chunks hinted with their own 201-minute plan), so the
# first chunk is one run of up to 4 s. A larger budget runs the smaller one's chunks
# first (docs/schedules.md#anytime).
EXACT_CHUNKS = (4, 8, 16, 32, 64, 128)

# From this budget (seconds of `time_limit_s`) on, the exact path also runs the LNS.
LNS_FROM_S = 4.0
LNS_SLICE = 0.1  # deterministic units per neighbourhood of an exact-size instance

EXACT_MODEL = "exact: no-overlap per robot + pairwise travel between zones"
EXACT_MODEL_NO_TRAVEL = "exact: no-overlap per robot (no travel between zones)"


def model_size(problem: Problem) -> tuple[int, int]:
    """(presence literals, travel order literals) of the exact model of `problem`."""
    tm = problem.instance.timing
    on: list[dict[int | None, int]] = [{} for _ in range(tm.n_robots)]
    intervals = 0
    for t in range(tm.n_tasks):
        robots = [problem.pinned[t]] if t in problem.pinned else tm.eligible_robots(t)
        for r in robots:
            if r in problem.unavailable and t not in problem.pinned:
                continue
            intervals += 1
            on[r][tm.task_zone[t]] = on[r].get(tm.task_zone[t], 0) + 1
    if not tm.has_travel:
        return intervals, 0
    orders = 0
    for counts in on:
        n = sum(counts.values())
        orders += (n * n - sum(c * c for c in counts.values())) // 2
    return intervals, orders


def fits_exact(problem: Problem) -> bool:
    intervals, orders = model_size(problem)
    return intervals <= EXACT_INTERVALS and intervals + orders <= EXACT_LIMIT


def solve_schedule(
    problem: Problem,
    *,
    time_limit_s: float = 10.0,
    workers: int = 1,
    hint: Schedule | None = None,
    seed: int = 0,
    wall_cap_s: float | None = None,
) -> ScheduleOutcome:
    """The best schedule found within `time_limit_s` (a deterministic budget: the same
    answer on a quiet and on a loaded machine), with what is proven about it.

    `problem` may carry pins (with fixed starts), unavailable robots and `not_before`: the
    remaining tasks of a living plan. `hint` is a previous plan; it seeds the search and is
    kept if nothing better is found and it is still feasible. `wall_cap_s` overrides the
    wall-clock safety net. DomainError when CP-SAT proves no schedule exists, or none is
    found in time."""
    if problem.instance.has_teams:  # docs/schedules.md#teams-in-time: the multi-skill model
        return solve_team_schedule(
            problem,
            time_limit_s=time_limit_s,
            workers=workers,
            hint=hint,
            seed=seed,
            wall_cap_s=wall_cap_s,
        )
    search = Search(time_limit_s, workers, seed, wall_cap_s=wall_cap_s)
    setup = _setup(problem, search, hint)
    if not fits_exact(problem):
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
    with contextlib.suppress(ValueError, DomainError):
        # Robots chosen while scheduling, by earliest finish among the pairs allowed: where
        # the success rates leave the choice free (a job shop) a far better start than the
        # time-free optimum's arbitrary assignment; kept only if it meets the objective's
        # ES condition and passes the check.
        feasible.offer(free_dispatch(problem, setup.pairs))
    return setup


def _solve_exact(setup: Setup, hint: Schedule | None) -> ScheduleOutcome:
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    travel = Travel.PAIRS if problem.instance.timing.has_travel else Travel.NONE
    name = EXACT_MODEL if travel is Travel.PAIRS else EXACT_MODEL_NO_TRAVEL
    model = ScheduleModel(problem, setup.scale, travel, setup.weights, setup.pairs)
    search.charge(model_cost(model.model))
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
    floors = bound_floors(problem, setup.pairs)
    floor_units = setup.scale.up(max(floors.values())) if setup.scale.exact else 0
    status, solver_bound = _chunks(setup, model, hint, floor_units)
    if status == "INFEASIBLE":
        raise proved_none()
    best = feasible.best()
    if best is None:
        raise none_found(search.time_limit_s, name)
    scale = setup.scale
    proven = scale.exact and status == "OPTIMAL" and es_proven
    if scale.exact:
        floors["CP-SAT search"] = scale.minutes(solver_bound)
    bound, source = best_bound(floors, best.makespan, proven)
    result = outcome(setup, best, "optimal" if proven else "feasible", name, bound, source)
    result.bounds = floors
    return result


def _chunks(
    setup: Setup, model: ScheduleModel, hint: Schedule | None, floor: int
) -> tuple[str, float]:
    """The exact model's search in chunks that end at `EXACT_CHUNKS` (each as long as all
    before it): each restarts from the best plan (hint) and keeps what the previous ones
    proved (makespan >= their bound). Past `LNS_FROM_S`, the second
    half of each chunk goes to the LNS over the exact model (it finds plans; the whole
    model proves them). A budget that ends inside a chunk runs a prefix of it: the same
    neighbourhoods, then CP-SAT for less deterministic time on the same start, which
    finds a subset of what the longer run finds. (last status, best bound, model units)."""
    search, feasible, scale = setup.search, setup.feasible, setup.scale
    bound, status = float(floor), "UNKNOWN"
    candidates = [large_candidates(setup, t) for t in range(setup.problem.instance.n_tasks)]
    for edge in EXACT_CHUNKS:
        if search.remaining() <= 0.005:
            break
        full = edge * DET_PER_S  # the models' build cost comes out of the first chunk
        seed_plan = feasible.best() or hint
        if seed_plan is not None:
            model.hint(seed_plan.assignment, [s.start for s in seed_plan.slots])
        chunk = model.model.clone()
        makespan = chunk.get_int_var_from_proto_index(model.makespan.index)
        # Only the lower side: an upper bound at the hint's makespan slowed the 36-task
        # proof from 0.28 to 0.65 units (the hint already starts the search there).
        chunk.add(makespan >= int(bound))
        lns = edge > LNS_FROM_S
        end = search.spent + (full - search.spent) / 2 if lns else full
        units = min(end, search.budget) - search.spent
        if units <= 0.005:
            break
        solver, status = search.run(chunk, "makespan", units, disjunctive=model.travel_pairs)
        search.need(search.spent)
        if status == "INFEASIBLE" and feasible.best() is None:
            return status, bound
        if status in ("OPTIMAL", "FEASIBLE"):
            feasible.offer_times(*model.read(solver))
        if status != "INFEASIBLE":
            bound = max(bound, solver.best_objective_bound)
        best = feasible.best()
        if best is not None:
            search.mark(best.makespan, scale.minutes(bound))
        if status == "OPTIMAL" or (best is not None and scale.up(best.makespan) <= bound):
            return "OPTIMAL", bound
        if lns:
            improve(setup, candidates, seconds=full - search.spent, slice_units=LNS_SLICE)
            best = feasible.best()
            if best is not None:
                search.mark(best.makespan)
    return status, bound


def _stage_success(setup: Setup, model: ScheduleModel, hint: Schedule | None) -> tuple[int, bool]:
    """Stage 1: the most ES a schedule reaches, and whether that is proven."""
    search, feasible = setup.search, setup.feasible
    model.model.add(model.es <= setup.es_bound)
    model.model.maximize(model.es)
    seed_plan = feasible.best() or hint
    if seed_plan is not None:
        model.hint(seed_plan.assignment, [s.start for s in seed_plan.slots])
    solver, status = search.run(
        model.model, "expected success", search.remaining() / 2, disjunctive=model.travel_pairs
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
