"""A run's current schedule (SPEC 16 "Time in living plans"): the schedule its decisions
make, re-timed by the execution reports the site sent (`app.domain.scheduling.reported`).

What `GET /runs/{id}/schedule`, the console's Gantt chart and the diff's "before" read: a
task reported done later than planned moves what waits for it. Only the reports with
times count (every report has one: `at`, or its arrival).
"""

from __future__ import annotations

from collections.abc import Iterable

from app.domain.problem import Problem
from app.domain.scheduling.reported import Reported, minutes_since, retime
from app.domain.scheduling.schedule import Schedule
from app.store.models import ExecutionReport, as_utc


def reported_minutes(problem: Problem, rows: Iterable[ExecutionReport]) -> dict[int, Reported]:
    """The reports of a timed problem's tasks in minutes of its plan, by task index."""
    origin = problem.instance.timing.start
    if origin is None:  # a plan without a wall clock cannot place a report
        return {}
    out: dict[int, Reported] = {}
    for row in rows:
        if not 0 <= row.task_index < problem.instance.n_tasks:
            continue
        start = None if row.started_at is None else minutes_since(origin, as_utc(row.started_at))
        end = None if row.ended_at is None else minutes_since(origin, as_utc(row.ended_at))
        if start is not None or end is not None:
            out[row.task_index] = Reported(start, end)
    return out


def with_reports(problem: Problem, planned: Schedule, rows: Iterable[ExecutionReport]) -> Schedule:
    """The planned schedule re-timed by the reports (itself when there are none)."""
    reported = reported_minutes(problem, rows)
    if not reported:
        return planned
    return retime(problem, planned, reported)
