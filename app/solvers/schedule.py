"""`schedule`: the exact scheduler of docs/schedules.md#schedulers on OR-Tools CP-SAT, as an
allocation method.

On a timed instance it decides who and when together (see `schedule_search`), and its
details say what is proven: `status` ("optimal" only when CP-SAT proved it), the
makespan as `objective_value`, its `bound` and `gap`, which `model` ran, the wall time,
the stages and the schedule. On an untimed instance there is nothing to schedule: it
answers with the exact allocation optimum (min-cost flow) and says so in `model`, so the
one-contract conformance suite holds for it like for every method.
"""

from __future__ import annotations

from typing import Any

from pydantic import BaseModel, ConfigDict, Field

from app.domain.errors import DomainError
from app.domain.models import Instance
from app.domain.problem import Problem
from app.domain.scheduling.list_schedule import sequence_schedule
from app.domain.scheduling.schedule import Schedule
from app.solvers.base import Solution, Solver, SolverInfo, SolverOptions
from app.solvers.cpsat.search import solve_schedule
from app.solvers.optimal import OptimalSolver


class HintEntry(BaseModel):
    """One task of a previous plan: its robot (name) and, optionally, its start."""

    model_config = ConfigDict(extra="forbid")

    task_id: int | str
    robot: str
    start: float | None = Field(default=None, ge=0)


class ScheduleOptions(SolverOptions):
    time_limit_s: float = Field(default=10.0, gt=0, le=120)
    workers: int = Field(default=1, ge=1, le=16)
    hint: list[HintEntry] | None = None


class ScheduleSolver(Solver):
    info = SolverInfo(
        name="schedule",
        description="Exact scheduler on OR-Tools CP-SAT: robots and start times together "
        "(durations, precedence, travel between zones, releases, deadlines, shifts, the "
        "workload cap); 'optimal' only when proven, else the bound and gap.",
        exact=True,
        limits="exact while its model has at most 20,000 literals (presence per task and "
        "robot, travel order literals only where travel applies) and 5,000 intervals; past "
        "that a load-balancing assignment, dispatch and a large-neighbourhood search over "
        "the exact model (never called optimal); time_limit_s <= 120, a deterministic "
        "budget (the same answer on any machine load)",
    )
    Options = ScheduleOptions
    forms_teams = True  # docs/allocation.md#teams: the multi-skill model, exact

    def _solve(self, problem: Problem, *, seed: int, options: Any) -> Solution:
        if not problem.instance.timed:
            solution = OptimalSolver()._solve(problem, seed=seed, options=None)
            solution.details["model"] = "untimed instance: the exact allocation optimum"
            return solution
        hint = None if options.hint is None else _hint_schedule(problem, options.hint)
        outcome = solve_schedule(
            problem,
            time_limit_s=options.time_limit_s,
            workers=options.workers,
            hint=hint,
            seed=seed,
        )
        schedule = outcome.schedule
        return Solution(schedule.assignment, details=outcome.details(), teams=schedule.teams)


def _hint_schedule(problem: Problem, entries: list[HintEntry]) -> Schedule | None:
    """A previous plan as a schedule of this problem, or None if it no longer is one."""
    instance: Instance = problem.instance
    index = {str(t.id): i for i, t in enumerate(instance.tasks)}
    placed: dict[int, tuple[int, float]] = {}
    for i, entry in enumerate(entries):
        t = index.get(str(entry.task_id))
        if t is None:
            raise DomainError(
                f"options.hint.{i}.task_id",
                f"unknown task id {entry.task_id!r}",
                code="unknown_task",
            )
        r = instance.robot_index(entry.robot)
        if r is None:
            raise DomainError(
                f"options.hint.{i}.robot", f"unknown robot '{entry.robot}'", code="unknown_robot"
            )
        placed[t] = (r, entry.start if entry.start is not None else float(i))
    if len(placed) != instance.n_tasks:
        return None  # a partial plan still helps CP-SAT less than its own list schedule
    sequences: list[list[int]] = [[] for _ in range(instance.n_robots)]
    for t in sorted(placed, key=lambda k: (placed[k][1], k)):
        sequences[placed[t][0]].append(t)
    try:
        return sequence_schedule(problem, sequences)
    except (ValueError, DomainError):
        return None
