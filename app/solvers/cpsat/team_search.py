"""Solving a timed problem with team tasks on CP-SAT (docs/schedules.md#teams-in-time).

The same objectives and the same meaning of "optimal" as `app.solvers.cpsat.search`, on
the multi-skill model of `team_model`: `success_then_makespan` maximises expected success
(stage 1; skipped when the list schedule of the time-free optimum, `optimal`'s min-cost
flow over units, is feasible: nothing beats that ES), then holds it and minimises the
makespan (stage 2); `makespan` holds ES >= `min_expected_success` and minimises. Every
answer is re-timed (earliest times for its per-robot orders, a team task starting when its
last member can) and must pass `check_schedule`; `status` is "optimal" only when CP-SAT
proved the makespan stage, the ES is proven and time values are whole at the model's scale.

Every team instance takes this exact model, whatever its size: the large-instance path
(`large.py`) plans one robot per task, so it never sees a team (a big team instance ends
with the best plan found in the budget, its bound and gap, never a false "optimal").
"""

from __future__ import annotations

import contextlib
from collections.abc import Mapping, Sequence

from ortools.sat.python import cp_model

from app.domain.errors import DomainError
from app.domain.metrics import expected_success
from app.domain.objective import ObjectiveKind
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.list_schedule import list_schedule, sequence_schedule
from app.domain.scheduling.schedule import Schedule
from app.solvers.cpsat.bounds import best_bound
from app.solvers.cpsat.common import (
    Search,
    makespan_floor,
    model_cost,
    none_found,
    proved_none,
)
from app.solvers.cpsat.outcome import ScheduleOutcome
from app.solvers.cpsat.team_dispatch import team_dispatch
from app.solvers.cpsat.team_model import TeamModel, TeamWeights, team_model_size
from app.solvers.cpsat.time_scale import TimeScale
from app.solvers.unit_flow import best_units
from app.solvers.units import UnitView

# The team model is built whole (no large-instance path plans teams yet): past this many
# literals (presences, unit assignments, travel orders) it is refused with a sentence
# rather than built for minutes (100 tasks on 5 robots over three zones: ~17,000).
TEAM_LIMIT = 60_000

TEAM_MODEL = (
    "exact: multi-skill project scheduling (a team's interval shared by optional per-robot "
    "presences, unit coverage, no-overlap per robot with travel)"
)


class _Found:
    """Feasible schedules so far with their integer ES, the objective's ES condition."""

    def __init__(self, problem: Problem, weights: TeamWeights) -> None:
        self.problem, self.weights = problem, weights
        self.found: list[tuple[int, Schedule]] = []
        self.floor: int | None = None
        self.target: int | None = None

    def es(self, schedule: Schedule) -> int:
        units = self.problem.instance.units
        return self.weights.of(schedule.assignment, schedule.teams, units)

    def offer(self, schedule: Schedule) -> None:
        if not check_schedule(self.problem, schedule):
            self.found.append((self.es(schedule), schedule))

    def offer_orders(
        self, sequences: Sequence[Sequence[int]], teams: Mapping[int, tuple[int, ...]]
    ) -> None:
        with contextlib.suppress(ValueError, DomainError):
            self.offer(sequence_schedule(self.problem, sequences, teams))

    def best_es(self) -> int | None:
        return max((es for es, _ in self.found), default=None)

    def best(self) -> Schedule | None:
        def ok(es: int) -> bool:
            if self.target is not None:
                return es == self.target
            return self.floor is None or es >= self.floor

        kept = [(s.makespan, -es, i) for i, (es, s) in enumerate(self.found) if ok(es)]
        return None if not kept else self.found[min(kept)[2]][1]


def solve_team_schedule(
    problem: Problem,
    *,
    time_limit_s: float = 10.0,
    workers: int = 1,
    hint: Schedule | None = None,
    seed: int = 0,
    wall_cap_s: float | None = None,
) -> ScheduleOutcome:
    """The best team schedule found within `time_limit_s` (deterministic budget), with what
    is proven. DomainError when CP-SAT proves none exists or none is found in time."""
    size = team_model_size(problem)
    if size > TEAM_LIMIT:
        raise DomainError(
            "tasks",
            f"the team schedule model of this instance would have {size:,} literals, above "
            f"its limit of {TEAM_LIMIT:,} (no large-instance path plans teams yet); plan it "
            "with 'optimal' or 'greedy', whose teams the list scheduler times "
            "(docs/schedules.md#teams-in-time)",
            code="too_large",
        )
    search = Search(time_limit_s, workers, seed, wall_cap_s=wall_cap_s)
    scale = TimeScale.of(problem)
    weights = TeamWeights(problem)
    found = _Found(problem, weights)
    view = UnitView.of(problem)
    flow = view.solution(best_units(view), {})
    es_bound = weights.of(flow.assignment, flow.teams, problem.instance.units)
    with contextlib.suppress(ValueError, DomainError):
        found.offer(list_schedule(problem, flow.assignment, flow.teams))
    if hint is not None:
        found.offer_orders(hint.sequences(problem.instance.n_robots), hint.teams)
    model = TeamModel(problem, scale, weights)
    search.charge(model_cost(model.model))
    if (plan := team_dispatch(problem, model.candidates)) is not None:
        found.offer_orders(*plan)
    es_proven = True
    if problem.objective.kind is ObjectiveKind.MAKESPAN:
        found.floor = _es_floor(problem, weights, es_bound)
        model.model.add(model.es >= found.floor)
    else:
        if found.best_es() == es_bound:
            found.target = es_bound  # proven: nothing beats the time-free optimum
        else:
            found.target, es_proven = _stage_success(model, search, found, es_bound, scale)
        model.model.add(model.es == found.target)
    model.model.minimize(model.makespan)
    # Hinted with the first plans only where stage 2 holds ES at a target those plans reach
    # (baseline_team at 10 s: 244 min hinted, 279 not). Under `makespan` the space is wide and
    # the first plans far from short (MSPSP set 2c: 49-62 and 32-52 against optima of
    # 22-43); hinted, the one-worker search followed them into worse plans (n30_l3_m8_01 40,
    # n30_l10_m15_00 36, against 39 and 34 unhinted). A caller's own hint is always used.
    automatic = problem.objective.kind is not ObjectiveKind.MAKESPAN
    _seed(model, (found.best() if automatic else None) or hint)
    solver, status = _makespan_stage(model, search)
    if status == "INFEASIBLE" and found.best() is None:
        raise proved_none()
    if status in ("OPTIMAL", "FEASIBLE"):
        found.offer_orders(*model.read(solver))
    best = found.best()
    if best is None:
        raise none_found(time_limit_s, TEAM_MODEL)
    proven = scale.exact and status == "OPTIMAL" and es_proven
    # CP-SAT's bound holds for the plan only when times are whole at the model's scale
    # (rounded-up durations make the model's makespans longer); else the chains' floor.
    floors = {"precedence chains and work": makespan_floor(problem)}
    if scale.exact and status != "INFEASIBLE":
        floors["CP-SAT search"] = scale.minutes(solver.best_objective_bound)
    bound, source = best_bound(floors, best.makespan, proven)
    search.mark(best.makespan, bound)
    return ScheduleOutcome(
        schedule=best,
        status="optimal" if proven else "feasible",
        model=TEAM_MODEL,
        objective=problem.objective.kind,
        makespan=best.makespan,
        bound=bound,
        gap=0.0 if best.makespan <= 0 else max(0.0, (best.makespan - bound) / best.makespan),
        expected_success=expected_success(problem.instance, best.assignment, best.teams),
        expected_success_bound=expected_success(problem.instance, flow.assignment, flow.teams),
        wall_s=search.elapsed(),
        stages=search.stages,
        bound_source=source,
        bounds=floors,
        budget=search.summary(),
        trajectory=search.trajectory,
    )


def _es_floor(problem: Problem, weights: TeamWeights, es_bound: int) -> int:
    """The least integer ES (free part) whose mean reaches `min_expected_success`."""
    n = problem.instance.n_tasks
    wanted = problem.objective.min_expected_success * n - weights.pinned_success
    floor = max(0, -(-round(wanted / weights.per_unit * 1e6) // 1_000_000))
    if es_bound < floor:
        best = (es_bound * weights.per_unit + weights.pinned_success) / n
        raise DomainError(
            "min_expected_success",
            f"no allocation under the cap reaches an expected success of "
            f"{problem.objective.min_expected_success:g}; the best is {best:.4f}",
            code="no_schedule",
        )
    return floor


def _makespan_stage(model: TeamModel, search: Search) -> tuple[cp_model.CpSolver, str]:
    """The makespan stage: one CP-SAT run with what is left of the budget."""
    # The one-robot path's rule (search.py): strong disjunctive propagation and the
    # objective-bound search only where travel literals make the model disjunctive. Without
    # travel (MSPSP-InstLib set 2c) the objective-bound search cost proofs and plans:
    # docs/benchmarks.md#multi-skill-project-scheduling-mspsp-instlib-set-2c.
    travel = model.tm.has_travel
    # Under `makespan` without travel (set 2c), the search branches on the starts, earliest
    # first, with linearization level 2: it reached the optimum on the two instances the
    # default search missed (n30_l9_m15_00 31 -> 30, n30_l12_m10_00 34 -> 33, both proven
    # in under 1.3 units) and proved 5 of 6 borderline ones (none before). Not with ES held
    # at a target (success_then_makespan), where fixing starts first ignores the ES.
    fixed = model.problem.objective.kind is ObjectiveKind.MAKESPAN and not travel
    if fixed:
        model.branch_on_starts()
    return search.run(
        model.model, "makespan", search.remaining(), disjunctive=travel, fixed_search=fixed
    )


def _seed(model: TeamModel, plan: Schedule | None) -> None:
    if plan is not None:
        model.hint(plan.assignment, plan.teams, [s.start for s in plan.slots])


def _stage_success(
    model: TeamModel, search: Search, found: _Found, es_bound: int, scale: TimeScale
) -> tuple[int, bool]:
    """Stage 1: the most ES a schedule reaches, and whether that is proven."""
    model.model.add(model.es <= es_bound)
    model.model.maximize(model.es)
    _seed(model, found.best())
    solver, status = search.run(
        model.model, "expected success", search.remaining() / 2, disjunctive=model.tm.has_travel
    )
    if status == "INFEASIBLE":
        raise proved_none()
    if status in ("OPTIMAL", "FEASIBLE"):
        found.offer_orders(*model.read(solver))
    reached = found.best_es()
    if reached is None:
        raise none_found(search.time_limit_s / 2, "stage 1, expected success")
    proven = reached == es_bound or (status == "OPTIMAL" and scale.exact)
    return reached, proven
