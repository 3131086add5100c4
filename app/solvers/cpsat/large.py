"""The large-instance path: past `EXACT_LIMIT`, a schedule with a proven bound, never
called optimal.

Measured here (2 shared cores): at 1,000 tasks x 20 robots a full scheduling model, even
without travel literals, found no schedule in 60 s, hint included; its bound stayed at
half of what a load relaxation proves. What makes such plans long is load: the success
objective pushes the best robots up to the cap. So the path decides in four steps:

1. Bound and assign: the LP relaxation of the assignment (`load_bound`, HiGHS) and the
   `AssignmentModel` (ES held at its target, or above the floor; the cap; per robot:
   shift start + work + one entry into each zone it visits <= T; minimise T). Both bounds
   on T are lower bounds on the makespan; the larger (or the chains') is the `bound`.
   With `FOLLOW_MIN_S` or more left it gets `ASSIGNMENT_SHARE` of the time, else all.
2. Time: the assignment (and the time-free optimum, already in hand) by the list
   scheduler and by earliest-finish dispatch within its per-class quotas.
3. Sequence, when `SEQUENCING_SHARE` of the time left is at least `SEQUENCING_MIN_S`:
   the exact model with pairwise travel on the best assignment so far, each task fixed
   to its robot: CP-SAT improves the per-robot orders and start times, hinted with the
   best schedule (at 200 x 20 it proves that assignment's optimum in under a second; at
   1,000 x 20 it improves nothing in 10 s).
4. Improve, until the time limit: the large-neighbourhood search (`lns`) over the exact
   model from the best schedule so far.

`details["model"]` names the steps that ran (and the LNS's neighbourhoods and
improvements).

With `success_then_makespan`, the ES target must already be reached by a feasible
schedule of the time-free optimum (else: a DomainError that says what to change); the
path does not search below the best ES.
"""

from __future__ import annotations

from app.domain.errors import DomainError
from app.solvers.cpsat.assignment_model import AssignmentModel
from app.solvers.cpsat.common import assignment_schedules, makespan_floor, none_found
from app.solvers.cpsat.lns import improve
from app.solvers.cpsat.load_bound import load_lower_bound
from app.solvers.cpsat.model import ScheduleModel, Travel
from app.solvers.cpsat.outcome import ScheduleOutcome, Setup, outcome

LARGE_MODEL = (
    "large-instance path: CP-SAT load-balancing assignment (travel as per-zone entries), "
    "list and earliest-finish schedules"
)
SEQUENCING_MODEL = ", CP-SAT sequencing of the best assignment"
LNS_MODEL = ", LNS over the exact model"
SEQUENCING_SHARE = 0.2  # of the time left; the LNS gets the rest
LP_MIN_S = 2.0  # below this the chains' bound has to do
LP_SHARE = 0.25  # of the time left, at most, for the LP bound
SEQUENCING_MIN_S = 3.0  # below this, building the sequencing model costs more than it gains
FOLLOW_MIN_S = 2.0  # below this the assignment takes all the time left
ASSIGNMENT_SHARE = 0.25  # of the time left, when the LNS (and sequencing) follow


def solve_large(setup: Setup) -> ScheduleOutcome:
    problem, search, feasible, scale = setup.problem, setup.search, setup.feasible, setup.scale
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
    lp_bound = 0.0
    if search.remaining() >= LP_MIN_S:
        lp_bound = load_lower_bound(
            problem,
            candidates,
            setup.weights,
            es_target=setup.es_target,
            es_floor=setup.es_floor,
            time_limit_s=search.remaining() * LP_SHARE,
        )
    assign = AssignmentModel(problem, scale, candidates, setup.weights)
    if setup.es_target is not None:
        assign.model.add(assign.es == setup.es_target)
    else:
        assign.model.add(assign.es >= setup.es_floor)
    assign.model.minimize(assign.makespan)
    seed_plan = feasible.best()
    if seed_plan is not None:
        assign.hint(seed_plan.assignment)
    follow = search.remaining() >= FOLLOW_MIN_S
    share = search.remaining() * (ASSIGNMENT_SHARE if follow else 1.0)
    solver, status = search.run(assign.model, "assignment", share, light_presolve=True)
    if status == "INFEASIBLE":
        raise DomainError(
            "max_deviation",
            "CP-SAT proved no assignment meets the workload cap at this expected success",
            code="no_schedule",
        )
    load_bound = lp_bound
    if status in ("OPTIMAL", "FEASIBLE"):
        for schedule in assignment_schedules(problem, assign.read(solver)):
            feasible.offer(schedule)
    if scale.exact:
        load_bound = max(load_bound, scale.minutes(solver.best_objective_bound))
    ran = LARGE_MODEL
    if follow and search.remaining() * SEQUENCING_SHARE >= SEQUENCING_MIN_S:
        _sequence(setup, search.remaining() * SEQUENCING_SHARE)
        ran += SEQUENCING_MODEL
    report = improve(setup, candidates)
    if report is not None:
        ran += f"{LNS_MODEL} ({report.neighbourhoods} neighbourhoods, {report.improved} improved)"
    best = feasible.best()
    if best is None:
        raise none_found(search.time_limit_s, ran)
    bound = min(best.makespan, max(makespan_floor(problem, setup.pairs), load_bound))
    return outcome(setup, best, "feasible", ran, bound)


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


def _sequence(setup: Setup, seconds: float) -> None:
    """Step 3: better orders and times for the best assignment so far."""
    problem, search, feasible = setup.problem, setup.search, setup.feasible
    best = feasible.best()
    if best is None:
        return
    robots = best.assignment
    travel = Travel.PAIRS if problem.instance.timing.has_travel else Travel.NONE
    fixed = {(t, r) for t, r in enumerate(robots)}
    model = ScheduleModel(problem, setup.scale, travel, setup.weights, fixed)
    model.model.add(model.makespan <= setup.scale.up(best.makespan))
    model.model.minimize(model.makespan)
    model.hint(robots, [s.start for s in best.slots])
    solver, status = search.run(model.model, "sequencing", seconds, light_presolve=True)
    if status in ("OPTIMAL", "FEASIBLE"):
        feasible.offer_times(*model.read(solver))
