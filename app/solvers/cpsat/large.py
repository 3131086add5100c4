"""The large-instance path: past `EXACT_LIMIT`, a schedule with a proven bound, never
called optimal.

Measured here (2 shared cores): at 1,000 tasks x 20 robots a full scheduling model, even
without travel literals, found no schedule in 60 s, hint included; its bound stayed at
half of what a load relaxation proves. What makes such plans long is load: the success
objective pushes the best robots up to the cap. The path runs a fixed sequence of stages,
each with a fixed deterministic budget, so a larger `time_limit_s` runs the smaller one's
stages first and then more LNS (docs/schedules.md#anytime):

1. Bound: the floors of `bounds` (critical path, heads and tails over the robots able)
   and the LP relaxation of the assignment (`load_bound`, HiGHS: deterministic; with
   each robot's zone and group entries, first head and last tail from a budget of
   `FULL_LP_FROM`).
2. Assign: the `AssignmentModel` (ES held at its target, or above the floor; the cap; per
   robot: shift start + work + one entry into each zone it visits <= T; minimise T) for
   `ASSIGN_UNITS`; its bound on T is one more floor. Then time it: the assignment (and
   the time-free optimum, already in hand) by the list scheduler and by earliest-finish
   dispatch within its per-class quotas, and dispatched again with the busiest robots'
   durations weighted (`_dispatch_busy`).
3. Sequence, for `SEQUENCE_UNITS`: the exact model on the best assignment so far, each
   task fixed to its robot: CP-SAT improves the per-robot orders and start times, hinted
   with the best schedule (at 200 x 20 it proves that assignment's optimum in under a
   second).
4. Improve, until the budget (where the speeds decide, first the load LP again with each
   robot's routes through the zones, a floor of its own: `_route_floor`): the
   large-neighbourhood search (`lns`) over the exact model
   from the best schedule so far, in whole slices (`loaded_first`: its robots neighbourhood
   starts from the most loaded robots on the critical path, the tasks after it floating).

`details["model"]` names the steps that ran (and the LNS's neighbourhoods and
improvements), `bound_source` the floor that bounds the bound.

With `success_then_makespan`, the ES target must already be reached by a feasible
schedule of the time-free optimum (else: a DomainError that says what to change); the
path does not search below the best ES.
"""

from __future__ import annotations

import contextlib

import numpy as np

from app.domain.errors import DomainError
from app.domain.scheduling.dispatch import dispatch_schedule, quotas_of
from app.domain.scheduling.zone_batches import batched_orders
from app.solvers.cpsat.assignment_model import AssignmentModel
from app.solvers.cpsat.bounds import Chains, best_bound, bound_floors, chains
from app.solvers.cpsat.common import (
    assignment_schedules,
    free_dispatch,
    model_cost,
    none_found,
    speeds_decide,
    task_classes,
)
from app.solvers.cpsat.lns import SLICE, improve
from app.solvers.cpsat.load_bound import Relaxation, load_relaxation
from app.solvers.cpsat.model import ScheduleModel, Travel
from app.solvers.cpsat.outcome import ScheduleOutcome, Setup, outcome

LARGE_MODEL = (
    "large-instance path: CP-SAT load-balancing assignment (travel as per-zone entries), "
    "list and earliest-finish schedules"
)
SEQUENCING_MODEL = ", CP-SAT sequencing of the best assignment"
LNS_MODEL = ", LNS over the exact model"
LOAD_LP = "load (LP relaxation of the assignment)"
ASSIGNMENT_BOUND = "load with zone entries (CP-SAT assignment)"
# Deterministic units for the assignment and for sequencing it: small, so that from a
# time limit of about a second on every run starts with the same stages (at 1,000 x 20
# the assignment, hinted with the time-free optimum, is feasible at once; the LNS
# improves what it leaves).
ASSIGN_UNITS = 0.3
SEQUENCE_UNITS = 0.5
SEQUENCE_BUILD = 0.1  # room kept for building the sequencing model
LP_COST_PER_PAIR = 2e-5  # the LP's modelled cost in deterministic units, per (task, robot)
# The full load LP from this budget (deterministic units: a time limit of about 1.5 s) on:
# below it, the plain one (0.1-0.3 s of CPU at 1,000 x 20), so a 1 s answer stays quick.
FULL_LP_FROM = 0.5
BUSY_DISPATCH = ", earliest-finish dispatch with the busiest robots' durations weighted"
# Robots with more work than this share of the most loaded one's count as busy. Measured
# at 1,000 x 20 (from 3,823 minutes): the outcome of one weight is erratic (3,771 at 0.3,
# 3,800 at 0.05, 4,270 at 0.1), so the step keeps the best of several.
BUSY_SHARE = 0.8
BUSY_PENALTIES = (0.05, 0.15, 0.25, 0.3, 0.35, 0.45, 0.6, 1.0)
DISPATCH_COST_PER_TASK = 1.5e-5  # deterministic units per task (47 ms at 1,000 tasks)
QUICK_DISPATCH = ", earliest-finish dispatch with slowness charged"
# Minutes charged per minute of slowness, one dispatch each. Measured on the second
# family (docs/benchmarks.md), 600 x 12 x 4 zones: 657 at 0, 559 at 1, 507 at 2, 503 at 3,
# 485 at 4; the best weight varies by site (1,000 x 20: 4, 200 x 5: 3): the best is kept.
SLOWNESS = (1.0, 2.0, 3.0, 4.0, 6.0)
LP_ROUNDED = ", load-LP assignments in zone-batched orders"
# Step 2d, where the speeds decide: the load LP's shares rounded to an assignment (each
# task to its largest share) with every zone entry priced these many times over (1: the
# bound's own LP), each in zone-batched orders for each travel weight (tail weight 0.5).
# Measured on the second family, 600 x 12 x 4 zones: the LP's assignment holds 4,341
# minutes of work where the best dispatch's holds 4,546 (the least possible: 4,319); in
# queue order it crosses the site 1,040 minutes (521), zone-batched 792 (467, weight 2).
# 1,000 x 20 x 4 zones: 425 at weight 1, where the dispatches' best is 429.
ENTRY_WEIGHTS = (1.0, 2.0, 3.0)
TRAVEL_WEIGHTS = (0.0, 1.0, 2.0, 4.0)
TAIL_WEIGHT = 0.5
BATCH_COST_PER_TASK = 5e-5  # deterministic units per task and order (60 ms at 600 x 12)
# Where the speeds decide, the load LP again with each robot's routes through the zones
# (`load_bound`'s `routes`), a floor only, so it runs after the plan's first stages (a
# small budget keeps them): step 2d rounds the entries LP's shares (on the second
# family's 600 x 12 x 4 zones, from the routes' shares its plan was 461 at 10 s where the
# entries' gave 453). Not on the first family: there it proved no more (600 x 12 x 4
# zones 401, 1,000 x 20 x 4 zones 417) and its cost would only cut the LNS short.
LOAD_ROUTES = "load with routes through the zones (LP relaxation)"
# The LNS's slice where the speeds decide, and how far past a neighbourhood the tasks
# float there. Measured (a callback on every answer): CP-SAT reports its answers to these
# neighbourhoods within the first 0.001 units of its clock and spends the rest of a slice
# proving or searching in vain, so a short slice runs many more of them; with the slice
# short, building the model costs more than solving it, and the tasks more than two hours
# past the window keep their times (`lns_model.Neighbourhood`'s `tail_minutes`).
# Second family, 600 x 12 x 4 zones, 30 s, search seeds 0-3 (mean):
# slice 0.2 453.75, 0.1 453.0, 0.05 449.0, 0.03 446.5, 0.02 446.25, 0.01 445.5; at 0.02
# with the tail cut at 60, 120 or 200 minutes 445.75, 443.5, 444.75 (0.01 and 120:
# 443.25). 1,000 x 20 x 4 zones at 60 s: 403 -> 395; 200 x 5 x 4 zones: 488 -> 483
# (docs/schedules.md#anytime).
UNRELATED_SLICE = 0.02
UNRELATED_TAIL_MINUTES = 120.0


def solve_large(setup: Setup) -> ScheduleOutcome:
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    if setup.es_floor is None and setup.es_target is None:
        raise DomainError(
            "tasks",
            "at the best expected success no schedule found meets every deadline and shift, "
            f"and past {problem.instance.n_tasks} tasks the scheduler does not search below "
            "the best expected success; use objective 'makespan' with a "
            "min_expected_success, or relax a deadline or a shift",
            code="no_schedule_found",
        )
    if setup.es_target is not None:
        target = setup.es_target
        feasible.keep(lambda es: es == target)
    tm = problem.instance.timing
    candidates = [_candidates(setup, t) for t in range(tm.n_tasks)]
    floors = bound_floors(problem, setup.pairs)
    chain = chains(problem, setup.pairs)
    relaxation = _load_lp(setup, candidates, chain)
    floors[LOAD_LP] = relaxation.minutes
    search.charge(LP_COST_PER_PAIR * sum(len(c) for c in candidates))
    ran = _assign(setup, candidates, floors)
    ran += _dispatch_busy(setup)
    unrelated = speeds_decide(setup.problem, setup.weights, candidates)
    if unrelated:
        ran += _dispatch_quick(setup)
    best = feasible.best()
    if best is not None:
        search.mark(best.makespan, min(best.makespan, max(floors.values())))
    # Step 2d, sequencing, then the LNS, only when step 2d and the sequencing fit whole:
    # every budget that runs them runs the same stages before them.
    # (a living plan's facts put robots where they worked: not for step 2d)
    batches = unrelated and not problem.pinned_starts
    batching = _lp_rounded_cost(candidates) if batches else 0.0
    if search.fits(batching + SEQUENCE_UNITS + SEQUENCE_BUILD):
        search.need(search.spent + batching + SEQUENCE_UNITS + SEQUENCE_BUILD)
        if batches:
            ran += _lp_rounded(setup, candidates, chain, relaxation.shares)
            search.mark(feasible.best().makespan)  # type: ignore[union-attr]
        if _sequence(setup, SEQUENCE_UNITS):
            ran += SEQUENCING_MODEL
            search.mark(feasible.best().makespan)  # type: ignore[union-attr]
        if unrelated and not _route_floor(setup, candidates, chain, floors):
            return _answer(setup, floors, ran)
        report = improve(
            setup,
            candidates,
            slice_units=UNRELATED_SLICE if unrelated else SLICE,
            loaded_first=True,
            effort_first=unrelated,
            tail_minutes=UNRELATED_TAIL_MINUTES if unrelated else None,
            compact=unrelated,
        )
        if report is not None:
            ran += (
                f"{LNS_MODEL} ({report.neighbourhoods} neighbourhoods, {report.improved} improved)"
            )
    return _answer(setup, floors, ran)


def _answer(setup: Setup, floors: dict[str, float], ran: str) -> ScheduleOutcome:
    best = setup.feasible.best()
    if best is None:
        raise none_found(setup.search.time_limit_s, ran)
    bound, source = best_bound(floors, best.makespan, False)
    result = outcome(setup, best, "feasible", ran, bound, source)
    result.bounds = floors
    return result


def _route_floor(
    setup: Setup, candidates: list[list[int]], chain: Chains, floors: dict[str, float]
) -> bool:
    """Where the speeds decide, before the LNS: the routes' LP (`LOAD_ROUTES`) for a plan
    without facts. False when it does not fit with a slice of the LNS after it: then
    nothing more runs, so every budget that runs the LNS ran this first (anytime)."""
    problem, search = setup.problem, setup.search
    if problem.pinned_starts:
        return True  # a fact puts a robot where it worked: no route from its start zone
    cost = LP_COST_PER_PAIR * sum(len(c) for c in candidates)
    if not search.fits(cost + UNRELATED_SLICE):
        return False
    search.need(search.spent + cost + UNRELATED_SLICE)
    floors[LOAD_ROUTES] = _full_lp(setup, candidates, chain, 1.0, routes=True).minutes
    search.charge(cost)
    best = setup.feasible.best()
    if best is not None:
        search.mark(best.makespan, min(best.makespan, max(floors.values())))
    return True


def _load_lp(setup: Setup, candidates: list[list[int]], chain: Chains) -> Relaxation:
    """The load LP with zone entries, first heads and last tails from a budget of
    `FULL_LP_FROM` units; the plain load LP (its rows without those) below it, or if
    HiGHS does not finish the full one before a third of the wall-clock net (on a machine
    loaded far past its cores: it takes 1.5-2.6 s of CPU at 1,000 x 20)."""
    problem, search = setup.problem, setup.search
    if search.budget >= FULL_LP_FROM:
        full = _full_lp(setup, candidates, chain, 1.0)
        if full.minutes > 0:
            return full
    plain = load_relaxation(
        problem,
        candidates,
        setup.weights,
        es_target=setup.es_target,
        es_floor=setup.es_floor,
        time_limit_s=max(0.1, search.wall_left() / 4),
    )
    return Relaxation(plain.minutes, None)  # the plain LP's shares see no travel


def _full_lp(
    setup: Setup,
    candidates: list[list[int]],
    chain: Chains,
    entry_weight: float,
    routes: bool = False,
) -> Relaxation:
    return load_relaxation(
        setup.problem,
        candidates,
        setup.weights,
        es_target=setup.es_target,
        es_floor=setup.es_floor,
        time_limit_s=max(0.1, setup.search.wall_left() / 3),
        heads=chain.heads,
        tails=chain.tails,
        scale=setup.scale,
        entry_weight=entry_weight,
        routes=routes,
    )


def _lp_rounded_cost(candidates: list[list[int]]) -> float:
    """Step 2d's modelled cost: its two more LPs and its zone-batched orders."""
    lps = len(ENTRY_WEIGHTS) - 1
    orders = len(ENTRY_WEIGHTS) * len(TRAVEL_WEIGHTS)
    pairs = sum(len(c) for c in candidates)
    return lps * LP_COST_PER_PAIR * pairs + orders * BATCH_COST_PER_TASK * len(candidates)


def _lp_rounded(
    setup: Setup, candidates: list[list[int]], chain: Chains, bound_shares: np.ndarray | None
) -> str:
    """Step 2d, where the speeds decide (`speeds_decide`): the load LP's shares at each of
    `ENTRY_WEIGHTS` rounded to an assignment, in zone-batched orders (`batched_orders`)
    for each of `TRAVEL_WEIGHTS` (what ran), for a plan without fixed starts."""
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    if bound_shares is None:
        # The full LP ran (the step fits only past `FULL_LP_FROM`) and HiGHS did not
        # finish before its share of the wall-clock net: the plan is not the budget's.
        search.wall_cut = True
        return ""
    tails = list(chain.tails)
    n, pairs = problem.instance.n_tasks, sum(len(c) for c in candidates)
    for weight in ENTRY_WEIGHTS:
        shares: np.ndarray | None = bound_shares
        if weight != 1.0:
            search.charge(LP_COST_PER_PAIR * pairs)
            shares = _full_lp(setup, candidates, chain, weight).shares
        if shares is None:
            search.wall_cut = True  # as above
            continue
        assignment = [int(np.argmax(row)) for row in shares]
        for travel in TRAVEL_WEIGHTS:
            search.charge(BATCH_COST_PER_TASK * n)
            with contextlib.suppress(ValueError, DomainError):
                orders = batched_orders(problem, assignment, tails, travel, TAIL_WEIGHT)
                feasible.offer_orders(orders)
    return LP_ROUNDED


def _assign(setup: Setup, candidates: list[list[int]], floors: dict[str, float]) -> str:
    """Step 2: the load-balancing assignment and its schedules; what ran."""
    problem, search, feasible, scale = setup.problem, setup.search, setup.feasible, setup.scale
    assign = AssignmentModel(problem, scale, candidates, setup.weights)
    if setup.es_target is not None:
        assign.model.add(assign.es == setup.es_target)
    else:
        assign.model.add(assign.es >= setup.es_floor)
    assign.model.minimize(assign.makespan)
    seed_plan = feasible.best()
    if seed_plan is not None:
        assign.hint(seed_plan.assignment)
    search.charge(model_cost(assign.model))
    search.need(search.spent + ASSIGN_UNITS)
    units = min(ASSIGN_UNITS, max(0.01, search.remaining()))
    solver, status = search.run(assign.model, "assignment", units, light_presolve=True)
    if status == "INFEASIBLE":
        raise DomainError(
            "max_deviation",
            "CP-SAT proved no assignment meets the workload cap at this expected success",
            code="no_schedule",
        )
    if status in ("OPTIMAL", "FEASIBLE"):
        for schedule in assignment_schedules(problem, assign.read(solver)):
            feasible.offer(schedule)
    if scale.exact:
        floors[ASSIGNMENT_BOUND] = scale.minutes(solver.best_objective_bound)
    return LARGE_MODEL


def _dispatch_busy(setup: Setup) -> str:
    """Step 2b: the best assignment's per-class quotas dispatched again, the busiest
    robots' durations weighted by each of `BUSY_PENALTIES` while choosing: they then take
    the tasks they are quick at (the same ES and loads; what ran)."""
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    best = feasible.best()
    if best is None:
        return ""
    tm = problem.instance.timing
    work = [0.0] * tm.n_robots
    for t, r in enumerate(best.assignment):
        work[r] += tm.duration(t, r)
    busy = [w > BUSY_SHARE * max(work) for w in work]
    groups = task_classes(problem)
    quotas = quotas_of(best.assignment, groups)
    for weight in BUSY_PENALTIES:
        search.charge(DISPATCH_COST_PER_TASK * tm.n_tasks)
        with contextlib.suppress(ValueError, DomainError):
            penalty = [weight if b else 0.0 for b in busy]
            feasible.offer(dispatch_schedule(problem, groups, quotas, penalty))
    return BUSY_DISPATCH


def _dispatch_quick(setup: Setup) -> str:
    """Step 2c, where the speeds decide (`speeds_decide`): earliest-finish dispatch with
    every allowed robot open, each minute a robot is slower at a task than the quickest
    open to it charged each of `SLOWNESS` minutes while choosing (what ran)."""
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    for slowness in SLOWNESS:
        search.charge(DISPATCH_COST_PER_TASK * problem.instance.n_tasks)
        with contextlib.suppress(ValueError, DomainError):
            feasible.offer(free_dispatch(problem, setup.pairs, slowness))
    return QUICK_DISPATCH


def _candidates(setup: Setup, t: int) -> list[int]:
    problem = setup.problem
    pin = problem.pinned.get(t)
    if pin is not None:
        return [pin]
    robots = problem.instance.timing.eligible_robots(t)
    return [
        r
        for r in robots
        if r not in problem.unavailable and (setup.pairs is None or (t, r) in setup.pairs)
    ]


def _sequence(setup: Setup, units: float) -> bool:
    """Step 3: better orders and times for the best assignment so far (False: nothing to
    sequence)."""
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    best = feasible.best()
    if best is None:
        return False
    robots = best.assignment
    travel = Travel.PAIRS if problem.instance.timing.has_travel else Travel.NONE
    fixed = {(t, r) for t, r in enumerate(robots)}
    model = ScheduleModel(problem, setup.scale, travel, setup.weights, fixed)
    model.model.add(model.makespan <= setup.scale.up(best.makespan))
    model.model.minimize(model.makespan)
    model.hint(robots, [s.start for s in best.slots])
    search.charge(model_cost(model.model))
    solver, status = search.run(model.model, "sequencing", units, light_presolve=True)
    if status in ("OPTIMAL", "FEASIBLE"):
        feasible.offer_times(*model.read(solver))
    return True
