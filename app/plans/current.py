"""A run's current schedule (docs/living-plans.md#the-runs-current-schedule): the schedule its
decisions make, re-timed by the execution reports the site sent (`app.domain.scheduling.reported`).

What `GET /runs/{id}/schedule`, the console's Gantt chart and the diff's "before" read: a
task reported done later than planned moves what waits for it. Only the reports with
times count (every report has one: `at`, or its arrival).
"""

from __future__ import annotations

import logging
from collections.abc import Iterable

from sqlalchemy.orm import Session, sessionmaker

from app.domain.problem import Problem
from app.domain.scheduling.reported import Reported, minutes_since, retime
from app.domain.scheduling.schedule import Schedule
from app.runs import views
from app.store import repository as repo
from app.store.models import ExecutionReport, as_utc

log = logging.getLogger("ltaa.plans")


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
    try:
        return retime(problem, planned, reported)
    except ValueError as exc:
        # Only a plan whose robot orders contradict its precedence, which no solver or
        # graph decision stores; the plan as decided is still the truest answer there is.
        log.warning("the reports could not re-time the plan: %s", exc)
        return planned


def current_schedule(
    *, sessions: sessionmaker[Session], run_id: str
) -> tuple[Problem, Schedule] | None:
    """A timed run's schedule as its decisions and its reports make it (None: untimed).
    StateConflictError (409) until the run has decided every task (`run_schedule`)."""
    planned = views.run_schedule(sessions=sessions, run_id=run_id)
    if planned is None:
        return None
    problem, schedule = planned
    with sessions() as session:
        rows = repo.execution_reports(session=session, run_id=run_id)
    return problem, with_reports(problem, schedule, rows)
