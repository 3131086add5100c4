"""A plan as Microsoft Project XML (MSPDI), for MS Project, ProjectLibre and P6 to open.

One Task per task (its id kept: as the UID when every id is a whole number, and always in
Text2, aliased "Task id", which the reader prefers), Start and Finish from the plan, its
Duration, its links with their types and lags, its features in Text1 (aliased
"Features"), one Resource per robot and one Assignment per (task, robot).

The file's calendar is "24 Hours", every minute working: the plan counts continuous
minutes, so in that calendar a task's Duration is exactly Finish - Start and a scheduler
opening the file computes the plan's dates from it. Lags are elapsed minutes (LagFormat 4)
for the same reason. Times are written as wall-clock times in the plan's own offset
(MSPDI dates carry no zone): the times the site works to.

Written as text rather than through an XML tree: 10,000 tasks export well inside the
benchmark's 2 s (benchmarks/exchange.py), and element order follows the MSPDI schema,
which MS Project checks.
"""

from __future__ import annotations

import re
from collections.abc import Mapping, Sequence
from datetime import datetime, timedelta
from typing import Any
from xml.sax.saxutils import escape

from app.domain.problem import Problem
from app.domain.scheduling.schedule import Schedule
from app.exchange.mspdi_read import ID_ALIAS, NAMESPACE, TEXT1, TEXT2

LINK_CODES = {"FF": 0, "FS": 1, "SF": 2, "SS": 3}
ELAPSED_MINUTES = 4  # LagFormat "em"
_INVALID_XML = re.compile("[\x00-\x08\x0b\x0c\x0e-\x1f\ufffe\uffff]")
_MAX_UID = 2**31 - 1


def _text(value: object) -> str:
    return escape(_INVALID_XML.sub("", str(value)))


def _duration(minutes: float) -> str:
    seconds = max(0, round(minutes * 60))
    return f"PT{seconds // 3600}H{seconds % 3600 // 60}M{seconds % 60}S"


def _uids(ids: Sequence[object]) -> list[int]:
    """The task ids as UIDs when they all are distinct whole numbers MS Project takes."""
    try:
        numbers = [int(str(i)) for i in ids]
    except ValueError:
        return list(range(1, len(ids) + 1))
    whole = all(str(n) == str(i) for n, i in zip(numbers, ids, strict=True))
    if whole and len(set(numbers)) == len(numbers) and all(0 < n <= _MAX_UID for n in numbers):
        return numbers
    return list(range(1, len(ids) + 1))


def _link(entry: Any) -> tuple[object, str, float]:
    """(predecessor id, type, lag minutes) of an `after` entry: a plain id (finish to start,
    no lag), a mapping {"task", "type", "lag"} or an object with those attributes."""
    if isinstance(entry, Mapping):
        return entry["task"], str(entry.get("type") or "FS"), float(entry.get("lag") or 0)
    if hasattr(entry, "task"):
        return entry.task, str(getattr(entry, "type", "FS")), float(getattr(entry, "lag", 0))
    return entry, "FS", 0.0


def _calendar() -> list[str]:
    days = "".join(
        f"<WeekDay><DayType>{d}</DayType><DayWorking>1</DayWorking><WorkingTimes><WorkingTime>"
        "<FromTime>00:00:00</FromTime><ToTime>00:00:00</ToTime></WorkingTime></WorkingTimes>"
        "</WeekDay>"
        for d in range(1, 8)
    )
    return [
        "<Calendars><Calendar><UID>1</UID><Name>24 Hours</Name><IsBaseCalendar>1</IsBaseCalendar>"
        f"<BaseCalendarUID>-1</BaseCalendarUID><WeekDays>{days}</WeekDays></Calendar></Calendars>"
    ]


def write_mspdi(
    problem: Problem,
    schedule: Schedule,
    *,
    project_name: str = "LTAA plan",
    start: datetime | None = None,
) -> bytes:
    """The plan as MSPDI, each task's links with their types and lags
    (docs/schedules.md#links). `start` is minute 0 when the schedule has none (ValueError
    when neither gives one)."""
    origin = schedule.start or start
    if origin is None:
        raise ValueError("an MS Project file needs the plan's start as a date-time")
    tasks, robots = problem.instance.tasks, problem.instance.robots
    uids = _uids([t.id for t in tasks])
    uid_of = {str(t.id): uid for t, uid in zip(tasks, uids, strict=True)}

    def at(minute: float) -> str:
        moment = origin + timedelta(seconds=round(minute * 60))
        return moment.replace(tzinfo=None).isoformat(timespec="seconds")

    finish = at(schedule.makespan)
    out = [
        '<?xml version="1.0" encoding="UTF-8" standalone="yes"?>',
        f'<Project xmlns="{NAMESPACE}"><SaveVersion>14</SaveVersion>',
        f"<Name>{_text(project_name)}</Name><Title>{_text(project_name)}</Title>",
        f"<ScheduleFromStart>1</ScheduleFromStart><StartDate>{at(0)}</StartDate>",
        f"<FinishDate>{finish}</FinishDate><CalendarUID>1</CalendarUID>",
        "<DefaultStartTime>00:00:00</DefaultStartTime><MinutesPerDay>1440</MinutesPerDay>",
        "<MinutesPerWeek>10080</MinutesPerWeek><DaysPerMonth>30</DaysPerMonth>",
        "<ExtendedAttributes>",
        f"<ExtendedAttribute><FieldID>{TEXT1}</FieldID><FieldName>Text1</FieldName>"
        "<Alias>Features</Alias></ExtendedAttribute>",
        f"<ExtendedAttribute><FieldID>{TEXT2}</FieldID><FieldName>Text2</FieldName>"
        f"<Alias>{ID_ALIAS}</Alias></ExtendedAttribute>",
        "</ExtendedAttributes>",
        *_calendar(),
        "<Tasks>",
    ]
    for number, (slot, uid) in enumerate(zip(schedule.slots, uids, strict=True), start=1):
        task = tasks[slot.task]
        entries = task.after
        out.append(
            f"<Task><UID>{uid}</UID><ID>{number}</ID><Name>{_text(task.name)}</Name>"
            f"<Active>1</Active><Manual>0</Manual><Type>0</Type><IsNull>0</IsNull>"
            f"<WBS>{number}</WBS><OutlineNumber>{number}</OutlineNumber>"
            f"<OutlineLevel>1</OutlineLevel><Start>{at(slot.start)}</Start>"
            f"<Finish>{at(slot.end)}</Finish><Duration>{_duration(slot.end - slot.start)}"
            "</Duration><DurationFormat>3</DurationFormat><Milestone>0</Milestone>"
            "<Summary>0</Summary>"
        )
        if task.release is not None:
            out.append("<ConstraintType>4</ConstraintType><CalendarUID>-1</CalendarUID>")
            out.append(f"<ConstraintDate>{at(task.release)}</ConstraintDate>")
        else:
            out.append("<ConstraintType>0</ConstraintType><CalendarUID>-1</CalendarUID>")
        if task.deadline is not None:
            out.append(f"<Deadline>{at(task.deadline)}</Deadline>")
        for entry in entries:
            pred, kind, lag = _link(entry)
            out.append(
                f"<PredecessorLink><PredecessorUID>{uid_of[str(pred)]}</PredecessorUID>"
                f"<Type>{LINK_CODES[kind]}</Type><CrossProject>0</CrossProject>"
                f"<LinkLag>{round(lag * 10)}</LinkLag><LagFormat>{ELAPSED_MINUTES}</LagFormat>"
                "</PredecessorLink>"
            )
        out.append(
            f"<ExtendedAttribute><FieldID>{TEXT1}</FieldID>"
            f"<Value>{_text(','.join(task.features))}</Value></ExtendedAttribute>"
            f"<ExtendedAttribute><FieldID>{TEXT2}</FieldID><Value>{_text(task.id)}</Value>"
            "</ExtendedAttribute></Task>"
        )
    out.append("</Tasks><Resources>")
    for r, robot in enumerate(robots, start=1):
        out.append(
            f"<Resource><UID>{r}</UID><ID>{r}</ID><Name>{_text(robot.name)}</Name>"
            "<Type>1</Type></Resource>"
        )
    out.append("</Resources><Assignments>")
    # One per (task, member): a team task (docs/allocation.md#teams) holds each member.
    pairs = [(s, uid, r) for s, uid in zip(schedule.slots, uids, strict=True) for r in s.members]
    for number, (slot, uid, member) in enumerate(pairs, start=1):
        out.append(
            f"<Assignment><UID>{number}</UID><TaskUID>{uid}</TaskUID>"
            f"<ResourceUID>{member + 1}</ResourceUID><Finish>{at(slot.end)}</Finish>"
            f"<Start>{at(slot.start)}</Start><Units>1</Units>"
            f"<Work>{_duration(slot.end - slot.start)}</Work></Assignment>"
        )
    out.append("</Assignments></Project>")
    return "\n".join(out).encode("utf-8")
