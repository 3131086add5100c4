"""A schedule as iCalendar (RFC 5545): one VEVENT per task, the robot as its RESOURCES (a
team task's members all in one RESOURCES list, docs/allocation.md#teams).

Written here rather than with a library: the format asks for little (a dozen properties,
text escaping, line folding), and the tests read what this writes with an independent
parser (the `icalendar` package), so the two cannot share a mistake. Times are in UTC
(RFC 5545 form 2, `...Z`): a fixed offset has no TZID a calendar could look up, and every
calendar shows UTC times in its reader's own zone.
"""

from __future__ import annotations

from datetime import UTC, datetime, timedelta

from app.domain.problem import Problem
from app.domain.scheduling.schedule import Schedule
from app.schedule_views.json_view import critical_tasks

PRODID = "-//LTAA//Robot task schedule//EN"
_LINE_OCTETS = 75  # RFC 5545 3.1: lines longer than this are folded


def _text(value: object) -> str:
    """TEXT escaping (RFC 5545 3.3.11)."""
    return (
        str(value)
        .replace("\\", "\\\\")
        .replace(";", "\\;")
        .replace(",", "\\,")
        .replace("\r\n", "\\n")
        .replace("\n", "\\n")
        .replace("\r", "\\n")
    )


def _fold(line: str) -> str:
    """Fold at 75 octets, never inside a UTF-8 character; each continuation starts with a
    space, which counts toward its 75."""
    out: list[str] = []
    current: list[str] = []
    size = 0
    for char in line:
        width = len(char.encode("utf-8"))
        if size + width > _LINE_OCTETS:
            out.append("".join(current))
            current, size = [" "], 1
        current.append(char)
        size += width
    out.append("".join(current))
    return "\r\n".join(out)


def _utc(moment: datetime) -> str:
    return moment.astimezone(UTC).strftime("%Y%m%dT%H%M%SZ")


def schedule_ics(
    problem: Problem,
    schedule: Schedule,
    *,
    calendar_name: str,
    uid_prefix: str,
    start: datetime | None = None,
) -> bytes:
    """The calendar of a schedule. `start` is minute 0 on the wall clock when the schedule
    has none; ValueError when neither gives one, or a time falls outside the years 1-9999."""
    origin = schedule.start or start
    if origin is None or origin.utcoffset() is None:
        raise ValueError("a calendar needs the plan's start as a date-time with an offset")
    tasks, robots = problem.instance.tasks, problem.instance.robots
    critical = critical_tasks(schedule)

    def at(seconds: int) -> str:
        try:
            return _utc(origin + timedelta(seconds=seconds))
        except OverflowError:
            raise ValueError(
                f"minute {seconds / 60:g} of the plan falls outside the years 1 to 9999"
            ) from None

    lines = [
        "BEGIN:VCALENDAR",
        "VERSION:2.0",
        f"PRODID:{PRODID}",
        "CALSCALE:GREGORIAN",
        "METHOD:PUBLISH",
        f"NAME:{_text(calendar_name)}",
        f"X-WR-CALNAME:{_text(calendar_name)}",
    ]
    stamp = at(0)  # the plan's start, so the same plan gives the same bytes
    for slot in schedule.slots:
        task, robot = tasks[slot.task], robots[slot.robot]
        description = f"Task {task.id} on robot {robot.name}"
        if slot.travel:
            description += f" after {slot.travel:g} min of travel"
        who = robot.display
        if slot.team:
            names = [robots[m].name for m in slot.team]
            pairs = zip(names, problem.instance.units[slot.task], strict=True)
            description = f"Task {task.id} by a team: " + ", ".join(f"{n} ({f})" for n, f in pairs)
            who = f"team of {len(names)}: " + ", ".join(names)
        if slot.task in critical:
            description += "; on the critical path"
        # Whole seconds (iCalendar has no finer time); an event ends after it starts.
        begin = round(slot.start * 60)
        end = max(round(slot.end * 60), begin + 1)
        lines += [
            "BEGIN:VEVENT",
            f"UID:{_text(f'{uid_prefix}-{task.id}')}",
            f"DTSTAMP:{stamp}",
            f"DTSTART:{at(begin)}",
            f"DTEND:{at(end)}",
            f"SUMMARY:{_text(f'{task.name} ({who})')}",
            # RFC 5545 3.8.1.10: a comma-separated list; each name escaped on its own.
            "RESOURCES:" + ",".join(_text(robots[m].name) for m in slot.members),
            f"DESCRIPTION:{_text(description)}",
        ]
        if slot.zone is not None:
            lines.append(f"LOCATION:{_text(slot.zone)}")
        if slot.task in critical:
            lines.append("CATEGORIES:critical path")
        lines.append("END:VEVENT")
    lines.append("END:VCALENDAR")
    return ("\r\n".join(_fold(line) for line in lines) + "\r\n").encode("utf-8")
