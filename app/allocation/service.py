"""From request body to response body. The one place an allocation response is built:
`POST /allocate` and `ltaa allocate --json` both call `allocate()`.
"""

from __future__ import annotations

import time
from collections.abc import Mapping, Sequence
from datetime import UTC, datetime
from typing import Any, Protocol

from app.allocation.schedule_schemas import ScheduleOut, ViolationOut
from app.allocation.schemas import (
    AllocateRequest,
    AllocateResponse,
    Assignment,
    InstanceRequest,
    MetricsOut,
    UsageOut,
)
from app.allocation.team_schemas import TeamMemberOut
from app.domain import catalog
from app.domain.errors import DomainError
from app.domain.metrics import compute_metrics, task_successes, workload
from app.domain.models import Instance, Robot, Task
from app.domain.objective import Objective, ObjectiveKind
from app.domain.pins import PinRequest, resolve_pins
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.schedule import Schedule
from app.domain.teams import team_problem
from app.reasoners.factory import ReasonerSettings
from app.schedule_views import schedule_json, violations_json
from app.solvers.base import Solution, Solver
from app.solvers.registry import get_solver


class InstanceOrder(Protocol):
    """An instance named in domain terms, as a run order holds it (app.runs.spec.RunOrder)."""

    @property
    def scenario(self) -> str | None: ...
    @property
    def tasks(self) -> Sequence[Task] | None: ...
    @property
    def robots(self) -> Sequence[Robot] | None: ...
    @property
    def travel(self) -> Mapping[str, Mapping[str, float]] | None: ...
    @property
    def start(self) -> datetime | None: ...


def resolve_instance(source: InstanceRequest | InstanceOrder) -> Instance:
    """The instance a POST /allocate body or a run order names: a built-in scenario (the
    timed ones, such as `baseline_timed`, included), or its own tasks and robots (a timed
    instance without `start` starts at the request's arrival, in whole seconds);
    DomainError naming the field if it names none."""
    tasks: Sequence[Task] | None
    robots: Sequence[Robot] | None
    if isinstance(source, InstanceRequest):
        tasks = None if source.tasks is None else [t.to_domain() for t in source.tasks]
        robots = None if source.robots is None else [r.to_domain() for r in source.robots]
    else:
        tasks, robots = source.tasks, source.robots
    return catalog.instance_of(
        source.scenario,
        tasks,
        robots,
        travel=source.travel,
        start=source.start,
        arrival=datetime.now(UTC).replace(microsecond=0),
    )


def build_problem(request: InstanceRequest) -> Problem:
    """The problem a request describes, with its pins and unavailable robots if it has
    any (POST /allocate; runs have none)."""
    # An explicit `"max_deviation": null` means no cap; leaving it out means the mode's.
    uncapped = "max_deviation" in request.model_fields_set and request.max_deviation is None
    instance = resolve_instance(request)
    if not isinstance(request, AllocateRequest):
        return Problem.build(instance, request.mode, request.max_deviation, uncapped=uncapped)
    pins = None
    if request.pinned or request.unavailable:
        pins = resolve_pins(
            instance,
            [
                PinRequest(
                    p.task_id,
                    p.robot,
                    None if p.team is None else [(m.robot, m.feature) for m in p.team],
                )
                for p in request.pinned
            ],
            request.unavailable,
        )
    return Problem.build(
        instance,
        request.mode,
        request.max_deviation,
        uncapped=uncapped,
        pinned=pins.pinned if pins else None,
        unavailable=pins.unavailable if pins else (),
        objective=Objective(ObjectiveKind(request.objective), request.min_expected_success),
        pinned_starts=_pinned_starts(instance, request),
        pinned_teams=pins.teams if pins else None,
    )


def _pinned_starts(instance: Instance, request: AllocateRequest) -> dict[int, float]:
    """Task index -> fixed start, for the pins that carry one (docs/api.md#plans-in-time)."""
    index = {str(task.id): t for t, task in enumerate(instance.tasks)}
    starts: dict[int, float] = {}
    for i, pin in enumerate(request.pinned):
        if pin.start is None:
            continue
        if not instance.timed:
            raise DomainError(
                f"pinned.{i}.start",
                "a pin's start applies to timed instances only: give every task a 'duration'",
            )
        starts[index[str(pin.task_id)]] = float(pin.start)  # resolve_pins checked the id
    return starts


def load_solver(name: str, settings: ReasonerSettings | None = None) -> Solver:
    """The registered solver, or a 4xx-mapped error when its optional dependencies are missing."""
    try:
        return get_solver(name, settings=settings)
    except ImportError as exc:
        raise DomainError(
            "solver",
            f"solver '{name}' is not available in this installation ({exc}); its "
            "optional dependencies may be missing (pip install 'ltaa[rl]')",
            code="solver_unavailable",
        ) from exc


def build_response(
    problem: Problem, solver: str, solution: Solution, *, seed: int, elapsed_ms: float
) -> AllocateResponse:
    instance = problem.instance
    teams = solution.teams
    s = task_successes(instance, solution.assignment, teams)
    timed = _timed_fields(problem, solution.details) if instance.timed else {}
    times = _assignment_times(timed.get("schedule"), instance.n_tasks)
    return AllocateResponse(
        solver=solver,
        mode=problem.mode,
        max_deviation=problem.cap.max_deviation,
        assignments=[
            Assignment(
                task_id=task.id,
                task_name=task.name,
                robot=instance.robots[r].name,
                success=float(s[t]),
                pinned=t in problem.pinned,
                team=_team_out(problem, t, teams[t]) if t in teams else None,
                **times[t],
            )
            for t, (task, r) in enumerate(zip(instance.tasks, solution.assignment, strict=True))
        ],
        metrics=MetricsOut.from_domain(
            compute_metrics(
                instance,
                solution.assignment,
                seed=seed,
                scope=problem.balance_scope,
                teams=teams,
            )
        ),
        usage=UsageOut.from_domain(solution.usage),
        elapsed_ms=elapsed_ms,
        **timed,
    )


def _team_out(problem: Problem, t: int, members: tuple[int, ...]) -> list[TeamMemberOut]:
    robots = problem.instance.robots
    return [
        TeamMemberOut(robot=robots[r].name, feature=f)
        for f, r in zip(problem.instance.units[t], members, strict=True)
    ]


def _assignment_times(schedule: ScheduleOut | None, n_tasks: int) -> list[dict[str, Any]]:
    """Per task (queue order), its entry of `schedule.tasks` as the time fields of its
    assignment: copied, so the two can never disagree. None without a schedule."""
    if schedule is None:
        return [{} for _ in range(n_tasks)]
    keys = ("start", "end", "start_at", "end_at", "zone", "travel")
    return [{key: getattr(slot, key) for key in keys} for slot in schedule.tasks]


def _timed_fields(problem: Problem, details: dict[str, Any]) -> dict[str, Any]:
    """The schedule block of an answer on a timed instance (docs/api.md#plans-in-time), and which
    part of it is exact: CP-SAT's own schedule (`schedule`), or the list scheduler's timing of
    another method's assignment (`app.solvers.timed`)."""
    schedule: Schedule | None = details.get("schedule")
    out: dict[str, Any] = {"schedule_model": details.get("schedule_model")}
    if "schedule_model" not in details:  # the method scheduled itself: CP-SAT
        status = details["status"]
        out = {
            "schedule_model": f"CP-SAT decided robots and start times together ({status}: "
            + ("the makespan is proven" if status == "optimal" else "bound and gap below")
            + ")",
            "status": status,
            "bound": details["bound"],
            "gap": details["gap"],
            "model": details["model"],
            "bound_source": details.get("bound_source"),
            "search": details.get("budget"),
        }
    if schedule is None:
        out["schedule_error"] = details.get("schedule_error")
        return out
    # Checked for every method, CP-SAT's too: the answer says what its schedule breaks.
    out["schedule"] = ScheduleOut.model_validate(schedule_json(problem, schedule))
    out["schedule_violations"] = [
        ViolationOut.model_validate(v)
        for v in violations_json(problem, check_schedule(problem, schedule))
    ]
    return out


def allocate(
    request: AllocateRequest, settings: ReasonerSettings | None = None
) -> AllocateResponse:
    """Validate, solve and measure. CPU-bound: callers on an event loop use a thread."""
    started = time.perf_counter()
    solver = load_solver(request.solver, settings)  # unknown solver reported before instance errors
    problem = build_problem(request)
    solution = solver.solve(problem, seed=request.seed, options=request.options)
    _check_solution(problem, solution, request.solver)
    elapsed_ms = (time.perf_counter() - started) * 1000
    return build_response(
        problem, request.solver, solution, seed=request.seed, elapsed_ms=round(elapsed_ms, 3)
    )


def _check_solution(problem: Problem, solution: Solution, solver: str) -> None:
    """Never return an allocation that is incomplete or breaks the cap
    (docs/allocation.md#the-workload-cap)."""
    n, r = problem.instance.n_tasks, problem.instance.n_robots
    a = solution.assignment
    if len(a) != n or any(not 0 <= robot < r for robot in a):
        raise RuntimeError(f"solver '{solver}' returned {len(a)} robot indices for {n} tasks")
    moved = [t for t, robot in problem.pinned.items() if a[t] != robot]
    moved += [t for t, team in problem.pinned_teams.items() if solution.teams.get(t) != team]
    if moved:
        raise RuntimeError(f"solver '{solver}' moved pinned task(s) {moved}")
    if problem.unavailable and any(a[t] in problem.unavailable for t in problem.free_tasks):
        raise RuntimeError(f"solver '{solver}' gave an unpinned task to an unavailable robot")
    _check_teams(problem, solution, solver)
    loads = workload(a, r, solution.teams)
    if not problem.cap.respected_by(loads):
        raise RuntimeError(f"solver '{solver}' returned an invalid allocation (loads {loads})")


def _check_teams(problem: Problem, solution: Solution, solver: str) -> None:
    """Every task on a robot that may take it; every team task's units covered by distinct
    eligible robots, its `robot` the first unit's member (docs/allocation.md#teams)."""
    instance = problem.instance
    teams = solution.teams
    eligible = instance.eligible
    for t, task in enumerate(instance.tasks):
        members = teams.get(t)
        if task.team is None:
            if members is not None or not eligible[t, solution.assignment[t]]:
                raise RuntimeError(f"solver '{solver}' gave task {task.id!r} an ineligible robot")
            continue
        if members is None:
            raise RuntimeError(f"solver '{solver}' returned no team for task {task.id!r}")
        why = team_problem(task, instance.robots, members)
        if why is None and members[0] != solution.assignment[t]:
            why = "its robot is not the member covering the first unit"
        # A pinned team keeps an unavailable member (docs/living-plans.md#pins-in-allocate).
        free = t not in problem.pinned
        if why is None and free and any(m in problem.unavailable for m in members):
            why = "a member is unavailable"
        if why is not None:
            raise RuntimeError(f"solver '{solver}' returned an invalid team for {task.id!r}: {why}")
