"""The shared list-scheduler hook: every method's answer on a timed instance gets a schedule.

`Solver.solve` calls `attach_schedule` with the details of the method's answer. Methods
that schedule themselves (`schedule`) leave a `schedule` in their details and are left
alone; for every other method the assignment is kept as it is and timed by the one serial
list scheduler (docs/schedules.md#schedulers), so every method has an expected success and a
makespan on the same instance. Nothing is hidden: the details carry the rules the schedule breaks
(`schedule_violations`, e.g. a deadline the assignment cannot meet), and an assignment
that gives a task to a robot that cannot take it has no schedule (`schedule` None and
`schedule_error` saying which task and robot).
"""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from app.domain.errors import DomainError
from app.domain.problem import Problem
from app.domain.scheduling.feasibility import check_schedule
from app.domain.scheduling.list_schedule import list_schedule
from app.domain.teams import Teams

LIST_SCHEDULER = "list scheduler (earliest start, precedence order) on the method's assignment"


def attach_schedule(
    problem: Problem,
    assignment: Sequence[int],
    details: dict[str, Any],
    teams: Teams | None = None,
) -> None:
    """Add the list scheduler's schedule of `assignment` (and its `teams`: every member
    works on the task over the same times, docs/allocation.md#teams) to an answer's
    `details`."""
    if not problem.instance.timed or "schedule" in details:
        return
    details["schedule_model"] = LIST_SCHEDULER
    try:
        schedule = list_schedule(problem, assignment, teams)
    except DomainError as exc:
        details["schedule"] = None
        details["schedule_error"] = exc.message
        return
    details["schedule"] = schedule
    details["schedule_violations"] = check_schedule(problem, schedule)
