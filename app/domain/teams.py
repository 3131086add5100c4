"""Team tasks and robot skills (docs/allocation.md#teams): the one eligibility rule.

A task with a `team` ({feature: count}) needs that many distinct robots at once, one robot
per *unit*; its units are the team's features in key order, each repeated `count` times.
A robot may cover a unit of feature f if f is in its `skills` (given) or it rates f above 0
(no skills given). A robot with `skills` may take a single-robot task only if every feature
of the task is a skill; a robot without `skills` may take any single-robot task, as before
teams existed, so an instance without the new fields is planned exactly as it was.

On a timed instance the duration map (docs/schedules.md#the-model) restricts eligibility
further; `app.domain.models.Instance.eligible` combines both, and every method reads that.

This module knows tasks and robots only through the attributes it reads (the protocols
below), so `models` can call its checks while it builds an Instance.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from typing import Protocol

import numpy as np

from app.domain.errors import DomainError


class Task(Protocol):
    """What this module reads of `app.domain.models.Task` (models imports this module)."""

    @property
    def id(self) -> int | str: ...
    @property
    def features(self) -> tuple[str, ...]: ...
    @property
    def team(self) -> Mapping[str, int] | None: ...
    @property
    def duration(self) -> object: ...


class Robot(Protocol):
    """What this module reads of `app.domain.models.Robot`."""

    @property
    def name(self) -> str: ...
    @property
    def success(self) -> Mapping[str, float]: ...
    @property
    def skills(self) -> tuple[str, ...] | None: ...


# Task index -> the robot covering each of its units, in unit order (team tasks only).
Teams = Mapping[int, tuple[int, ...]]


def units_of(task: Task) -> tuple[str, ...]:
    """The features of a team task's units, in key order; () for a single-robot task."""
    if task.team is None:
        return ()
    return tuple(f for f, count in task.team.items() for _ in range(count))


def unit_count(task: Task) -> int:
    """What the task adds to the loads: one per unit of a team, one for a single robot."""
    return len(units_of(task)) or 1


def covers(robot: Robot, feature: str) -> bool:
    """May `robot` cover a team unit of `feature`?"""
    if robot.skills is not None:
        return feature in robot.skills
    return robot.success.get(feature, 0.0) > 0.0


def may_take(robot: Robot, task: Task) -> bool:
    """May `robot` take (single-robot) task or cover at least one unit of a team task?"""
    if task.team is not None:
        return any(covers(robot, f) for f in task.team)
    return robot.skills is None or all(f in robot.skills for f in task.features)


def skill_mask(tasks: Sequence[Task], robots: Sequence[Robot]) -> np.ndarray:
    """E[t, r] from skills alone (untimed eligibility)."""
    return np.array([[may_take(r, t) for r in robots] for t in tasks], dtype=bool)


def team_success(task: Task, robots: Sequence[Robot], members: Sequence[int]) -> float:
    """The mean over the task's units of the covering member's rate for the unit's feature."""
    units = units_of(task)
    return float(np.mean([robots[r].success[f] for f, r in zip(units, members, strict=True)]))


def team_problem(task: Task, robots: Sequence[Robot], members: Sequence[int]) -> str | None:
    """Why `members` is not a valid team for `task` (coverage, distinct, eligible), or None."""
    units = units_of(task)
    if len(members) != len(units):
        return f"{len(members)} members for {len(units)} units; one robot per unit"
    if len(set(members)) != len(members):
        return "a robot covers two units; a team's members are distinct"
    for f, r in zip(units, members, strict=True):
        if not covers(robots[r], f):
            return f"robot '{robots[r].name}' cannot cover '{f}' (not in its skills)"
    return None


def check_skills(robots: Sequence[Robot]) -> None:
    for i, robot in enumerate(robots):
        if robot.skills is None:
            continue
        for skill in robot.skills:
            if skill not in robot.success:
                raise DomainError(
                    f"robots.{i}.skills",
                    f"robot '{robot.name}' lists skill '{skill}' but does not rate it; add "
                    f"'{skill}' to its success rates or remove the skill",
                )


def check_teams(tasks: Sequence[Task], robots: Sequence[Robot]) -> None:
    """The bad inputs of docs/allocation.md#teams, each naming the task and the feature.
    Runs after every task's features were checked to be rated by every robot."""
    for i, task in enumerate(tasks):
        if task.team is None:
            _check_single(i, task, robots)
            continue
        where = f"tasks.{i}.team"
        label = f"task {task.id!r}"
        if set(task.features) != set(task.team):
            raise DomainError(
                f"tasks.{i}.features",
                f"{label}: features {sorted(task.features)} disagree with the team's features "
                f"{sorted(task.team)}; a team task's features are its team's keys (send one "
                "of them, or both equal)",
            )
        if isinstance(task.duration, Mapping):
            raise DomainError(
                f"tasks.{i}.duration",
                f"{label} is a team task: give one number of minutes (every member is busy "
                "for all of it), not a per-robot map",
            )
        for feature, count in task.team.items():
            if isinstance(count, bool) or not isinstance(count, int) or count < 1:
                raise DomainError(
                    f"{where}.{feature}",
                    f"{label}: the team needs a whole number of robots at least 1 for "
                    f"'{feature}', got {count!r}; drop the feature or ask for 1 or more",
                )
            able = [r.name for r in robots if covers(r, feature)]
            if count > len(able):
                can = f"{len(able)} can ({', '.join(able)})" if able else "none can"
                raise DomainError(
                    f"{where}.{feature}",
                    f"{label}: the team needs {count} distinct robots covering '{feature}', "
                    f"but only {can}; lower the count or give more robots the skill",
                )
        _check_matching(i, task, robots)


def _check_single(i: int, task: Task, robots: Sequence[Robot]) -> None:
    if any(may_take(r, task) for r in robots):
        return
    # No robot may take it, so every robot lists skills.
    nobody = [f for f in task.features if not any(f in (r.skills or ()) for r in robots)]
    if nobody:
        problem = f"no robot has the skill {', '.join(repr(f) for f in nobody)}"
    else:
        needs = ", ".join(repr(f) for f in task.features)
        problem = f"no single robot has every skill it needs ({needs})"
    raise DomainError(
        f"tasks.{i}.features",
        f"task {task.id!r}: no eligible robot can take it: {problem}; add the skill to a "
        "robot, or make it a team task (`team`) so several robots share it",
    )


def unit_matching(options: Sequence[Sequence[int]]) -> dict[int, int]:
    """A largest assignment of distinct robots to units, as robot -> unit (augmenting paths:
    a team has a few units). `options[u]` lists the robots that may cover unit u, in the order
    they are tried."""
    holder: dict[int, int] = {}

    def place(unit: int, seen: set[int]) -> bool:
        for r in options[unit]:
            if r in seen:
                continue
            seen.add(r)
            if r not in holder or place(holder[r], seen):
                holder[r] = unit
                return True
        return False

    for unit in range(len(options)):
        place(unit, set())
    return holder


def _check_matching(i: int, task: Task, robots: Sequence[Robot]) -> None:
    """Every unit by a distinct robot at once: a bipartite matching of units to robots."""
    units = units_of(task)
    options = [[r for r, robot in enumerate(robots) if covers(robot, f)] for f in units]
    matched = len(unit_matching(options))
    if matched < len(units):
        features = ", ".join(f"'{f}'" for f in task.team or {})
        raise DomainError(
            f"tasks.{i}.team",
            f"task {task.id!r} needs {len(units)} distinct robots at once to cover "
            f"{features}, but at most {matched} of the fleet can be matched to its units; "
            "lower a count or give more robots the skills",
        )
