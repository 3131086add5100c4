"""From request body to response body. The one place an allocation response is built:
`POST /allocate` and `ltaa allocate --json` both call `allocate()`.
"""

from __future__ import annotations

import time
from datetime import UTC, datetime
from typing import Any

from app.api.schemas.allocation import (
    AllocateRequest,
    AllocateResponse,
    Assignment,
    InstanceRequest,
    MetricsOut,
    UsageOut,
)
from app.api.schemas.schedule import ScheduleOut, ViolationOut
from app.domain import catalog
from app.domain.errors import DomainError
from app.domain.metrics import compute_metrics
from app.domain.models import Instance
from app.domain.objective import Objective, ObjectiveKind
from app.domain.pins import resolve_pins
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.schedule import Schedule
from app.reasoners.factory import ReasonerSettings
from app.schedules import schedule_json, violations_json
from app.solvers.base import Solution, Solver
from app.solvers.registry import get_solver


def resolve_instance(request: InstanceRequest) -> Instance:
    """The instance a request describes; DomainError naming the field if it describes none."""
    return catalog.instance_of(
        request.scenario,
        None if request.tasks is None else [t.to_domain() for t in request.tasks],
        None if request.robots is None else [r.to_domain() for r in request.robots],
        travel=request.travel,
        start=request.start,
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
            instance, [(p.task_id, p.robot) for p in request.pinned], request.unavailable
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
    s = instance.success
    return AllocateResponse(
        solver=solver,
        mode=problem.mode,
        max_deviation=problem.cap.max_deviation,
        assignments=[
            Assignment(
                task_id=task.id,
                task_name=task.name,
                robot=instance.robots[r].name,
                success=float(s[t, r]),
                pinned=t in problem.pinned,
            )
            for t, (task, r) in enumerate(zip(instance.tasks, solution.assignment, strict=True))
        ],
        metrics=MetricsOut.from_domain(
            compute_metrics(instance, solution.assignment, seed=seed, scope=problem.balance_scope)
        ),
        usage=UsageOut.from_domain(solution.usage),
        elapsed_ms=elapsed_ms,
        **(_timed_fields(problem, solution.details) if instance.timed else {}),
    )


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
    if moved:
        raise RuntimeError(f"solver '{solver}' moved pinned task(s) {moved}")
    if problem.unavailable and any(a[t] in problem.unavailable for t in problem.free_tasks):
        raise RuntimeError(f"solver '{solver}' gave an unpinned task to an unavailable robot")
    loads = [a.count(i) for i in range(r)]
    if not problem.cap.respected_by(loads):
        raise RuntimeError(f"solver '{solver}' returned an invalid allocation (loads {loads})")
