"""A schedule as CSV: a header and one row per task, in queue order, for spreadsheets; a team
task (docs/allocation.md#teams) has one row per member, its `feature` the unit it covers and
`travel_min` that member's own way there, so a filter on `robot` reads a robot's day."""

from __future__ import annotations

import csv
import io

from app.domain.problem import Problem
from app.domain.scheduling.schedule import Schedule
from app.schedule_views.json_view import critical_tasks

COLUMNS = (
    "task_id",
    "task_name",
    "robot",
    "zone",
    "start_min",
    "end_min",
    "duration_min",
    "travel_min",
    "start_at",
    "end_at",
    "critical",
    "feature",  # last, so readers of the earlier columns read them where they were
)


def _number(minutes: float) -> str:
    # Plain decimals (never 1e+06), whole minutes without a fraction.
    return f"{minutes:.6f}".rstrip("0").rstrip(".")


def _cell(value: object) -> object:
    """Text a spreadsheet would run as a formula (=, +, -, @ first) is prefixed with a
    quote, as OWASP advises for CSV files opened in spreadsheets; numbers stay numbers."""
    if isinstance(value, str) and value[:1] in ("=", "+", "-", "@", "\t", "\r"):
        return "'" + value
    return value


def schedule_csv(problem: Problem, schedule: Schedule) -> str:
    tasks, robots = problem.instance.tasks, problem.instance.robots
    critical = critical_tasks(schedule)
    buffer = io.StringIO()
    # RFC 4180 line ends; the csv module quotes a name holding a comma or a quote.
    writer = csv.writer(buffer, lineterminator="\r\n")
    writer.writerow(COLUMNS)
    units = problem.instance.units
    for slot in schedule.slots:
        task = tasks[slot.task]
        # One row per (task, member); a single-robot task's feature cell stays empty.
        features = units[slot.task] if slot.team else ("",)
        for robot, feature in zip(slot.members, features, strict=True):
            writer.writerow(
                (
                    _cell(task.id),
                    _cell(task.name),
                    _cell(robots[robot].name),
                    _cell(slot.zone or ""),
                    _number(slot.start),
                    _number(slot.end),
                    _number(slot.end - slot.start),
                    _number(slot.travel_of(robot)),
                    schedule.wall_clock(slot.start) or "",
                    schedule.wall_clock(slot.end) or "",
                    "yes" if slot.task in critical else "no",
                    _cell(feature),
                )
            )
    return buffer.getvalue()
