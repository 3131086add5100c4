"""The rules a timed instance obeys (docs/schedules.md#the-model), checked once when an Instance is
built.

Every error is a DomainError whose field is the dotted path into the request
(`tasks.4.after`, `travel.A.C`, `robots.2.available`) and whose message names the task
and says how to fix it. The checks run in the order a user fixes things: each field on
its own, then the structure (cycles, travel pairs), then what the numbers together allow
(deadline chains, shifts). The result is the instance's TimeModel.
"""

from __future__ import annotations

import math
from collections.abc import Mapping, Sequence
from datetime import datetime
from typing import Any, Protocol

from app.domain.errors import DomainError
from app.domain.links import Link, check_links
from app.domain.time_model import TimeModel, unbounded


# What the rules read of a task and a robot (app.domain.models builds an Instance from
# them and calls these rules, so the rules name the fields, not the classes).
class Task(Protocol):
    @property
    def id(self) -> int | str: ...
    @property
    def name(self) -> str: ...
    @property
    def duration(self) -> float | Mapping[str, float] | None: ...
    @property
    def after(self) -> tuple[int | str | Link, ...]: ...
    @property
    def zone(self) -> str | None: ...
    @property
    def release(self) -> float | None: ...
    @property
    def deadline(self) -> float | None: ...


class Robot(Protocol):
    @property
    def name(self) -> str: ...
    @property
    def zone(self) -> str | None: ...
    @property
    def available(self) -> tuple[float, float] | None: ...


def has_time_fields(
    tasks: Sequence[Task], robots: Sequence[Robot], travel: Any, start: Any
) -> bool:
    if travel is not None or start is not None:
        return True
    if any(r.zone is not None or r.available is not None for r in robots):
        return True
    return any(
        t.duration is not None
        or t.after
        or t.zone is not None
        or t.release is not None
        or t.deadline is not None
        for t in tasks
    )


def _label(task: Task) -> str:
    return f"task {task.id!r} ({task.name})"


def _minutes(field: str, value: Any, what: str, *, positive: bool = False) -> float:
    ok = isinstance(value, int | float) and not isinstance(value, bool) and math.isfinite(value)
    if not ok or value < 0 or (positive and value == 0):
        sign = "a positive" if positive else "a non-negative"
        raise DomainError(field, f"{what} must be {sign} number of minutes, got {value!r}")
    return float(value)


def check_timing(
    tasks: Sequence[Task],
    robots: Sequence[Robot],
    travel: Mapping[str, Mapping[str, float]] | None,
    start: datetime | None,
) -> TimeModel:
    _require_durations(tasks, robots, travel, start)
    names = [r.name for r in robots]
    durations = tuple(_durations(i, t, names) for i, t in enumerate(tasks))
    links = check_links([t.id for t in tasks], [t.after for t in tasks], [_label(t) for t in tasks])
    release = tuple(
        0.0 if t.release is None else _minutes(f"tasks.{i}.release", t.release, "a release")
        for i, t in enumerate(tasks)
    )
    deadline = tuple(
        unbounded(
            None
            if t.deadline is None
            else _minutes(f"tasks.{i}.deadline", t.deadline, "a deadline", positive=True)
        )
        for i, t in enumerate(tasks)
    )
    shifts = tuple(_shift(i, r) for i, r in enumerate(robots))
    if start is not None and (not isinstance(start, datetime) or start.utcoffset() is None):
        raise DomainError(
            "start", "the plan's start needs a date, a time and a UTC offset (RFC 3339)"
        )
    zones, task_zone, robot_zone = _zones(tasks, robots)
    matrix = _travel_matrix(zones, travel, tasks, robots, task_zone, robot_zone)
    model = TimeModel(
        durations=durations,
        links=links,
        release=release,
        deadline=deadline,
        zones=zones,
        task_zone=task_zone,
        robot_zone=robot_zone,
        travel_minutes=matrix,
        shifts=shifts,
        start=start,
    )
    _check_deadline_chains(model, tasks)
    _check_shifts_fit(model, tasks, robots)
    return model


def _require_durations(
    tasks: Sequence[Task], robots: Sequence[Robot], travel: Any, start: Any
) -> None:
    timed = next((i for i, t in enumerate(tasks) if t.duration is not None), None)
    if timed is None:
        where = _first_time_field(tasks, robots, travel, start)
        raise DomainError(
            where,
            "time fields need a timed instance: give every task a 'duration' in minutes "
            "(or leave out every time field for an untimed plan)",
            code="not_timed",
        )
    for i, t in enumerate(tasks):
        if t.duration is None:
            raise DomainError(
                f"tasks.{i}.duration",
                f"{_label(t)} has no duration; in a timed instance (task "
                f"{tasks[timed].id!r} has one) every task needs one",
                code="missing_duration",
            )


def _first_time_field(
    tasks: Sequence[Task], robots: Sequence[Robot], travel: Any, start: Any
) -> str:
    for i, t in enumerate(tasks):
        for name in ("after", "zone", "release", "deadline"):
            if getattr(t, name) not in (None, ()):
                return f"tasks.{i}.{name}"
    for i, r in enumerate(robots):
        for name in ("zone", "available"):
            if getattr(r, name) is not None:
                return f"robots.{i}.{name}"
    return "travel" if travel is not None else "start"


def _durations(i: int, task: Task, names: Sequence[str]) -> tuple[float | None, ...]:
    field = f"tasks.{i}.duration"
    value = task.duration
    if not isinstance(value, Mapping):
        d = _minutes(field, value, f"the duration of {_label(task)}", positive=True)
        return tuple(d for _ in names)
    if not value:
        raise DomainError(field, f"{_label(task)}: the duration map names no robot")
    for key in value:
        if key not in names:
            raise DomainError(
                f"{field}.{key}",
                f"{_label(task)}: unknown robot '{key}' in the duration map; the fleet has: "
                f"{', '.join(names)}",
                code="unknown_robot",
            )
    return tuple(
        None
        if name not in value
        else _minutes(
            f"{field}.{name}", value[name], f"the duration of {_label(task)}", positive=True
        )
        for name in names
    )


def _shift(i: int, robot: Robot) -> tuple[float, float]:
    if robot.available is None:
        return (0.0, math.inf)
    field = f"robots.{i}.available"
    pair = robot.available
    if isinstance(pair, str | bytes) or not isinstance(pair, Sequence) or len(pair) != 2:
        raise DomainError(field, f"robot '{robot.name}': a shift is [start, end] in minutes")
    a = _minutes(f"{field}.0", pair[0], f"the shift start of robot '{robot.name}'")
    b = _minutes(f"{field}.1", pair[1], f"the shift end of robot '{robot.name}'")
    if b <= a:
        raise DomainError(
            field, f"robot '{robot.name}': the shift ends ({b:g}) before it starts ({a:g})"
        )
    return (a, b)


def _zones(
    tasks: Sequence[Task], robots: Sequence[Robot]
) -> tuple[tuple[str, ...], tuple[int | None, ...], tuple[int | None, ...]]:
    seen: dict[str, int] = {}

    def zone_index(field: str, name: Any) -> int:
        if not isinstance(name, str) or not name.strip():
            raise DomainError(field, f"a zone is a non-empty name, got {name!r}")
        return seen.setdefault(name, len(seen))

    with_zone = next((t for t in tasks if t.zone is not None), None)
    task_zone: list[int | None] = []
    for i, t in enumerate(tasks):
        if t.zone is None and with_zone is not None:
            raise DomainError(
                f"tasks.{i}.zone",
                f"{_label(t)} has no zone; when any task has one ({_label(with_zone)} is in "
                f"'{with_zone.zone}') every task needs one, to know what travel it costs",
                code="missing_zone",
            )
        task_zone.append(None if t.zone is None else zone_index(f"tasks.{i}.zone", t.zone))
    for i, r in enumerate(robots):
        if r.zone is not None and with_zone is None:
            raise DomainError(
                f"robots.{i}.zone",
                f"robot '{r.name}' starts in zone '{r.zone}' but no task has a zone; give "
                "the tasks zones too, or leave out the robot's",
            )
    robot_zone = tuple(
        None if r.zone is None else zone_index(f"robots.{i}.zone", r.zone)
        for i, r in enumerate(robots)
    )
    return tuple(seen), tuple(task_zone), robot_zone


def _travel_matrix(
    zones: Sequence[str],
    travel: Mapping[str, Mapping[str, float]] | None,
    tasks: Sequence[Task],
    robots: Sequence[Robot],
    task_zone: Sequence[int | None],
    robot_zone: Sequence[int | None],
) -> tuple[tuple[float, ...], ...]:
    given: dict[tuple[str, str], float] = {}
    if travel is not None and not isinstance(travel, Mapping):
        raise DomainError("travel", 'travel is a map of maps of minutes: {"A": {"B": 6}}')
    for a, row in (travel or {}).items():
        if not isinstance(row, Mapping):
            raise DomainError(f"travel.{a}", 'each zone maps to its neighbours: {"B": 6}')
        for b, minutes in row.items():
            m = _minutes(f"travel.{a}.{b}", minutes, f"travel from '{a}' to '{b}'")
            if a == b and m != 0:
                raise DomainError(
                    f"travel.{a}.{b}", "travel within a zone is 0 minutes; leave it out"
                )
            given[(a, b)] = m
    n = len(zones)
    matrix = [[0.0] * n for _ in range(n)]
    for i, a in enumerate(zones):
        for j, b in enumerate(zones):
            if i == j:
                continue
            pair = given.get((a, b), given.get((b, a)))
            if pair is None:
                users = _zone_users(zones, (i, j), tasks, robots, task_zone, robot_zone)
                raise DomainError(
                    f"travel.{a}.{b}",
                    f"no travel time between zones '{a}' and '{b}' ({users}); add "
                    f'"travel": {{"{a}": {{"{b}": <minutes>}}}}',
                    code="missing_travel",
                )
            matrix[i][j] = pair
    return quickest_routes(matrix)


def quickest_routes(matrix: list[list[float]]) -> tuple[tuple[float, ...], ...]:
    """A robot takes the quickest way between two zones, through others if that is quicker
    (Floyd-Warshall). So travel obeys the triangle inequality, which the exact scheduler's
    pairwise travel constraints rely on: an entry that a detour beats is lowered to it."""
    n = len(matrix)
    best = [list(row) for row in matrix]
    for k in range(n):
        for i in range(n):
            via = best[i][k]
            for j in range(n):
                if via + best[k][j] < best[i][j]:
                    best[i][j] = via + best[k][j]
    return tuple(tuple(row) for row in best)


def _zone_users(
    zones: Sequence[str],
    pair: tuple[int, int],
    tasks: Sequence[Task],
    robots: Sequence[Robot],
    task_zone: Sequence[int | None],
    robot_zone: Sequence[int | None],
) -> str:
    parts = []
    for z in pair:
        task = next((t for t, k in zip(tasks, task_zone, strict=True) if k == z), None)
        if task is not None:
            parts.append(f"{_label(task)} is in '{zones[z]}'")
        else:
            robot = next(r for r, k in zip(robots, robot_zone, strict=True) if k == z)
            parts.append(f"robot '{robot.name}' starts in '{zones[z]}'")
    return "; ".join(parts)


def _check_deadline_chains(model: TimeModel, tasks: Sequence[Task]) -> None:
    """A deadline earlier than the task's earliest finish: its release, its predecessors
    on their shortest durations and its own shortest duration (robots ignored)."""
    finish = model.earliest_finish
    for t in model.order:
        if finish[t] <= model.deadline[t] + 1e-9:
            continue
        chain = [t]
        while True:  # walk back through the predecessor that ends last
            preds = model.predecessors[chain[-1]]
            if not preds:
                break
            last = max(preds, key=lambda p: finish[p])
            if finish[last] <= model.release[chain[-1]]:
                break
            chain.append(last)
        chain.reverse()
        steps = ", then ".join(
            f"{tasks[k].id!r} ({model.shortest(k):g} min at the shortest)" for k in chain
        )
        first = chain[0]
        since = (
            f"from the release at minute {model.release[first]:g}, " if model.release[first] else ""
        )
        raise DomainError(
            f"tasks.{t}.deadline",
            f"{_label(tasks[t])} cannot end by its deadline (minute {model.deadline[t]:g}): "
            f"{since}{steps} end at minute {finish[t]:g} at the earliest; move the deadline or "
            "the release, or shorten the chain",
            code="impossible_deadline",
        )


def _check_shifts_fit(model: TimeModel, tasks: Sequence[Task], robots: Sequence[Robot]) -> None:
    """Some robot that may take the task must be able to do it inside its shift, between
    the task's earliest start (release, predecessors) and its deadline."""
    starts, finish = model.earliest
    for t in range(model.n_tasks):
        earliest = starts[t]
        fits = False
        for r in model.eligible_robots(t):
            a, b = model.shifts[r]
            end = max(max(earliest, a) + model.duration(t, r), finish[t])
            if end <= min(model.deadline[t], b) + 1e-9:
                fits = True
                break
        if fits:
            continue
        tried = "; ".join(
            f"'{robots[r].name}' takes {model.duration(t, r):g} min, shift "
            f"[{model.shifts[r][0]:g}, {model.shifts[r][1]:g}]"
            for r in model.eligible_robots(t)
        )
        window = f"it can start at minute {earliest:g}"
        if math.isfinite(model.deadline[t]):
            window += f" and must end by {model.deadline[t]:g}"
        raise DomainError(
            f"tasks.{t}.duration",
            f"no robot can fit {_label(tasks[t])} into its shift: {window} ({tried}); "
            "lengthen a shift, move the release or deadline, or let another robot take it",
            code="no_shift_fits",
        )
