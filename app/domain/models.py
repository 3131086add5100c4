"""Tasks, robots and the instance they form, with the success model S(r, t).

The time fields (docs/schedules.md#the-model: durations, `after`, zones, releases, deadlines,
shifts, travel, `start`) are optional and default to "absent": an instance without them is the
untimed instance of docs/allocation.md#success-and-balance, built and compared exactly as before.
Their rules live in `app.domain.timing_rules`; their index view (what schedulers read) in
`app.domain.time_model`.
"""

from __future__ import annotations

import dataclasses
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from functools import cached_property

import numpy as np

from app.domain.errors import DomainError
from app.domain.links import Link
from app.domain.teams import check_skills, check_teams, skill_mask, unit_count, units_of
from app.domain.time_model import TimeModel
from app.domain.timing_rules import check_timing, has_time_fields

MAX_TASKS = 10_000
MAX_ROBOTS = 100
# Longest name, label, feature or task id (as text) a request may carry; the app tables
# size their name columns from it.
MAX_NAME_CHARS = 200

TaskId = int | str
# Minutes: one number for every robot, or a per-robot map (a robot it omits cannot take it).
Duration = float | Mapping[str, float]


@dataclass(frozen=True)
class Task:
    id: TaskId
    name: str
    features: tuple[str, ...]
    type: str = "Custom"
    # docs/schedules.md#the-model, all optional. hash=False: a per-robot map is not hashable.
    duration: Duration | None = dataclasses.field(default=None, hash=False)
    # Plain ids: finish-to-start, no lag; a Link: typed, with a lag (docs/schedules.md#links).
    after: tuple[TaskId | Link, ...] = ()
    zone: str | None = None
    release: float | None = None  # earliest start, minutes from the plan's start
    deadline: float | None = None  # latest end, minutes from the plan's start
    # docs/allocation.md#teams: {feature: count}, distinct robots at once; None: one robot.
    team: Mapping[str, int] | None = dataclasses.field(default=None, hash=False)

    @property
    def after_ids(self) -> tuple[TaskId, ...]:
        """The ids of the tasks it waits for, whatever its links' types."""
        return tuple(a.task if isinstance(a, Link) else a for a in self.after)


@dataclass(frozen=True)
class Robot:
    name: str
    success: Mapping[str, float]
    label: str = ""
    description: str = ""
    zone: str | None = None  # where it starts (docs/schedules.md#the-model)
    available: tuple[float, float] | None = None  # its shift [start, end], minutes
    # docs/allocation.md#teams: the features it may work on; None: any it rates (above 0 in a team)
    skills: tuple[str, ...] | None = None

    @property
    def display(self) -> str:
        return self.label or self.name


@dataclass(frozen=True)
class Instance:
    """An ordered task queue and a robot fleet. Validated on construction."""

    tasks: tuple[Task, ...]
    robots: tuple[Robot, ...]
    # docs/schedules.md#the-model: minutes between zones ({"A": {"B": 6}}, symmetric when one
    # direction is given) and the wall-clock time of minute 0 (timezone-aware).
    travel: Mapping[str, Mapping[str, float]] | None = dataclasses.field(default=None, hash=False)
    start: datetime | None = None
    # The checked index view of the time fields; None for an untimed instance.
    _time_model: TimeModel | None = dataclasses.field(
        default=None, init=False, repr=False, compare=False, hash=False
    )

    def __post_init__(self) -> None:
        validate_instance(self.tasks, self.robots)
        if has_time_fields(self.tasks, self.robots, self.travel, self.start):
            model = check_timing(self.tasks, self.robots, self.travel, self.start)
            if self.restricted_by_skills:
                # One eligibility rule (docs/allocation.md#teams): what the skills forbid has
                # no duration, so every scheduler reading the time model honours it too.
                model = model.without(self._skill_mask)
                _check_someone_takes_each(self.tasks, self.robots, model.eligibility())
            object.__setattr__(self, "_time_model", model)

    @property
    def timed(self) -> bool:
        """Does any task have a duration? (Then every task has one: docs/schedules.md#the-model.)"""
        return self._time_model is not None

    @property
    def timing(self) -> TimeModel:
        """The time fields as indexes and numbers; only for a timed instance."""
        if self._time_model is None:
            raise ValueError("an untimed instance has no time model; check `timed` first")
        return self._time_model

    @cached_property
    def _skill_mask(self) -> np.ndarray:
        return skill_mask(self.tasks, self.robots)

    @property
    def restricted_by_skills(self) -> bool:
        return any(robot.skills is not None for robot in self.robots)

    @cached_property
    def eligible(self) -> np.ndarray:
        """E[t, r]: may robot r take task t (a team task: cover one of its units)? The one
        rule of docs/allocation.md#teams: the robots' skills, and on a timed instance the
        duration map (one that omits r makes (t, r) ineligible). All true without either."""
        if self._time_model is not None:
            mask = self._time_model.eligibility()
        elif self.restricted_by_skills:
            mask = self._skill_mask.copy()
        else:
            mask = np.ones((self.n_tasks, self.n_robots), dtype=bool)
        mask.setflags(write=False)
        return mask

    @cached_property
    def has_teams(self) -> bool:
        return any(task.team is not None for task in self.tasks)

    @cached_property
    def units(self) -> tuple[tuple[str, ...], ...]:
        """Per task, the features of its team's units in key order; () for one robot."""
        return tuple(units_of(task) for task in self.tasks)

    @cached_property
    def loads_added(self) -> tuple[int, ...]:
        """Per task, what it adds to the loads: its units, or 1 for a single-robot task."""
        return tuple(unit_count(task) for task in self.tasks)

    @cached_property
    def n_units(self) -> int:
        """The loads' total: tasks, with a team task counted once per unit."""
        return sum(self.loads_added)

    @property
    def n_tasks(self) -> int:
        return len(self.tasks)

    @property
    def n_robots(self) -> int:
        return len(self.robots)

    @property
    def target_load(self) -> float:
        """W = total units / robots (n_tasks / n_robots without team tasks)."""
        return self.n_units / self.n_robots

    @cached_property
    def features(self) -> tuple[str, ...]:
        """Every feature some task needs, in first-seen order."""
        seen: dict[str, None] = {}
        for task in self.tasks:
            for f in task.features:
                seen.setdefault(f, None)
        return tuple(seen)

    @cached_property
    def success(self) -> np.ndarray:
        """S[t, r] = mean over the task's features of the robot's success rate."""
        column = {f: i for i, f in enumerate(self.features)}
        rates = np.array(
            [[robot.success[f] for robot in self.robots] for f in self.features], dtype=float
        )
        need = np.zeros((self.n_tasks, len(self.features)))
        for t, task in enumerate(self.tasks):
            for f in task.features:
                need[t, column[f]] = 1.0 / len(task.features)
        s = need @ rates
        s.setflags(write=False)
        return s

    def robot_index(self, name_or_label: str) -> int | None:
        """Find a robot by key or display label, case-insensitively."""
        wanted = name_or_label.strip().lower()
        for i, robot in enumerate(self.robots):
            if wanted in (robot.name.lower(), robot.display.lower()):
                return i
        return None


def validate_instance(tasks: Sequence[Task], robots: Sequence[Robot]) -> None:
    if not tasks:
        raise DomainError("tasks", "the task queue is empty; send at least one task")
    if len(tasks) > MAX_TASKS:
        raise DomainError(
            "tasks",
            f"{len(tasks)} tasks exceeds the limit of {MAX_TASKS:,} per request",
            code="too_large",
        )
    if not robots:
        raise DomainError("robots", "the fleet is empty; send at least one robot")
    if len(robots) > MAX_ROBOTS:
        raise DomainError(
            "robots",
            f"{len(robots)} robots exceeds the limit of {MAX_ROBOTS} per request",
            code="too_large",
        )
    _check_robot_names(robots)
    for i, robot in enumerate(robots):
        if not robot.success:
            raise DomainError(f"robots.{i}.success", "rate at least one feature")
        for feature, p in robot.success.items():
            if not (isinstance(p, int | float) and 0.0 <= float(p) <= 1.0):
                raise DomainError(
                    f"robots.{i}.success.{feature}",
                    f"success probability {p!r} is outside [0, 1]",
                )
    ids: set[str] = set()
    for i, task in enumerate(tasks):
        key = str(task.id)
        if key in ids:
            raise DomainError(f"tasks.{i}.id", f"duplicate task id {task.id!r}")
        ids.add(key)
        if not task.features:
            raise DomainError(f"tasks.{i}.features", "a task needs at least one feature")
        if len(set(task.features)) != len(task.features):
            raise DomainError(
                f"tasks.{i}.features", "a feature is listed twice; list each feature once"
            )
        for feature in task.features:
            missing = [r.name for r in robots if feature not in r.success]
            if missing:
                where = "features" if task.team is None else f"team.{feature}"
                named = "" if task.team is None else f"task {task.id!r}: "
                raise DomainError(
                    f"tasks.{i}.{where}",
                    f"{named}unknown feature '{feature}': not rated by robot(s) "
                    f"{', '.join(missing)}; "
                    "every robot must rate every feature a task needs",
                )
    check_skills(robots)
    check_teams(tasks, robots)


# Reasoners name robots in markdown ("**Decision**: Light Robot", "Light Robot: 12"), so a
# name or label must be unambiguous and free of the characters that structure the reply.
_RESERVED = set("*`|:#[]\n\r")


def _check_robot_names(robots: Sequence[Robot]) -> None:
    owner: dict[str, int] = {}
    for i, robot in enumerate(robots):
        for field, value in (("name", robot.name), ("label", robot.label)):
            key = value.strip().lower()
            if field == "name" and not key:
                raise DomainError(f"robots.{i}.name", "robot name must not be empty")
            if not key:
                continue
            bad = sorted(_RESERVED & set(value))
            if bad:
                raise DomainError(
                    f"robots.{i}.{field}",
                    f"{field} '{value}' contains {', '.join(map(repr, bad))}, "
                    "which reasoner replies use as markup; remove it",
                )
            if key in owner and owner[key] != i:
                raise DomainError(
                    f"robots.{i}.{field}",
                    f"duplicate robot {field} '{value}': robot {owner[key]} "
                    "already uses it as a name or label; names and labels "
                    "must identify one robot each",
                )
            owner[key] = i


def _check_someone_takes_each(
    tasks: Sequence[Task], robots: Sequence[Robot], eligible: np.ndarray
) -> None:
    for t, task in enumerate(tasks):
        if not eligible[t].any():
            raise DomainError(
                f"tasks.{t}.duration",
                f"task {task.id!r}: no eligible robot can take it: its duration map names only "
                "robots whose skills lack a feature it needs "
                f"({', '.join(repr(f) for f in task.features)}); name a robot with the skills",
            )
