"""Pins and unavailable robots as a request names them (task ids, robot names) -> indexes.

The domain's Problem takes indexes; requests name tasks by id and robots by name (or
label). Every error names the offending entry by its dotted path in the request.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass, field

from app.domain.errors import DomainError
from app.domain.models import Instance, TaskId
from app.domain.teams import covers, units_of


@dataclass(frozen=True)
class Pins:
    pinned: dict[int, int]  # task index -> robot index
    unavailable: frozenset[int]
    teams: dict[int, tuple[int, ...]] = field(default_factory=dict)  # task -> member per unit


@dataclass(frozen=True)
class PinRequest:
    """One pin as a request names it: a task id and its robot, or for a team task its whole
    team as (robot, feature) entries, one per unit (`robot` then optional: the member
    covering the first unit, as answers read; docs/living-plans.md#pins-in-allocate)."""

    task_id: TaskId
    robot: str | None
    team: Sequence[tuple[str, str]] | None = None


def resolve_pins(
    instance: Instance,
    pinned: Sequence[PinRequest],
    unavailable: Sequence[str],
    *,
    pinned_field: str = "pinned",
    unavailable_field: str = "unavailable",
) -> Pins:
    # Task ids are unique as text (validate_instance), so 10 and "10" name the same task.
    task_at = {str(task.id): t for t, task in enumerate(instance.tasks)}
    known_robots = ", ".join(r.name for r in instance.robots)
    pins: dict[int, int] = {}
    teams: dict[int, tuple[int, ...]] = {}
    pinned_by: dict[int, int] = {}
    for i, pin in enumerate(pinned):
        task_id, robot_name = pin.task_id, pin.robot
        t = task_at.get(str(task_id))
        if t is None:
            raise DomainError(
                f"{pinned_field}.{i}.task_id",
                f"unknown task id {task_id!r}: no task in the queue has it",
                code="unknown_task",
            )
        if t in pins:
            raise DomainError(
                f"{pinned_field}.{i}.task_id",
                f"task {task_id!r} is pinned twice ({pinned_field}.{pinned_by[t]} already "
                "pins it); pin each task once",
                code="duplicate_pin",
            )
        where = f"{pinned_field}.{i}"
        members = _pin_shape(instance, t, pin, where)
        r = None
        if robot_name is not None:
            r = instance.robot_index(robot_name)
            if r is None:
                raise DomainError(
                    f"{where}.robot",
                    f"unknown robot '{robot_name}' (pin of task {task_id!r}); the fleet has: "
                    f"{known_robots}",
                    code="unknown_robot",
                )
        if members is not None:
            if r is not None and r != members[0]:
                raise DomainError(
                    f"{where}.robot",
                    f"robot '{robot_name}' is not the member covering the first unit of task "
                    f"{task_id!r} ('{instance.robots[members[0]].name}', as answers read "
                    "`robot`); give that robot or leave `robot` out",
                    code="team_pin",
                )
            r, teams[t] = members[0], members
        assert r is not None  # _pin_shape refuses a pin with neither a robot nor a team
        pins[t], pinned_by[t] = r, i
    off: dict[int, int] = {}
    for i, robot_name in enumerate(unavailable):
        r = instance.robot_index(robot_name)
        if r is None:
            raise DomainError(
                f"{unavailable_field}.{i}",
                f"unknown robot '{robot_name}'; the fleet has: {known_robots}",
                code="unknown_robot",
            )
        if r in off:
            raise DomainError(
                f"{unavailable_field}.{i}",
                f"robot '{robot_name}' is listed twice ({unavailable_field}.{off[r]} already "
                "names it); list each robot once",
                code="duplicate_robot",
            )
        off[r] = i
    if len(off) == instance.n_robots:
        raise DomainError(
            unavailable_field,
            f"every robot ({known_robots}) is unavailable; no robot is left to take the "
            "unpinned tasks",
            code="no_robot_left",
        )
    return Pins(pinned=pins, unavailable=frozenset(off), teams=teams)


def _pin_shape(instance: Instance, t: int, pin: PinRequest, where: str) -> tuple[int, ...] | None:
    """A pin's team in unit order (None for a one-robot pin): a team task is pinned with its
    whole team, a one-robot task with its robot; DomainError naming the entry otherwise."""
    task = instance.tasks[t]
    if pin.team is None:
        if task.team is not None:
            raise DomainError(
                f"{where}.team",
                f"task {task.id!r} is a team task ({_needs(task.team)}); pin it with its whole "
                'team, `team`: [{"robot", "feature"}, ...], one entry per unit '
                "(docs/living-plans.md#pins-in-allocate)",
                code="team_pin",
            )
        if pin.robot is None:
            raise DomainError(
                f"{where}.robot",
                f"give the robot task {task.id!r} is pinned on",
                code="missing_robot",
            )
        return None
    if task.team is None:
        raise DomainError(
            f"{where}.team",
            f"task {task.id!r} is a one-robot task; pin it with `robot`, not `team`",
            code="not_a_team",
        )
    return pinned_team(instance, t, pin.team, f"{where}.team")


def pinned_team(
    instance: Instance, t: int, entries: Sequence[tuple[str, str]], where: str
) -> tuple[int, ...]:
    """A team as a request gives it (a pin, a review's override), (robot, feature) per unit in
    any order, checked as a team of task `t` (one distinct robot per unit, each eligible and
    able to cover its unit's feature, every unit covered) and returned in unit order: the
    members of one feature in the order given. DomainError naming the entry (`where`.j.robot,
    ...)."""
    task, robots = instance.tasks[t], instance.robots
    need = dict(task.team or {})
    given: dict[str, list[int]] = {f: [] for f in need}
    seen: dict[int, int] = {}
    for j, (name, feature) in enumerate(entries):
        if feature not in need:
            raise DomainError(
                f"{where}.{j}.feature",
                f"task {task.id!r} has no unit of '{feature}'; its team is {_needs(need)}",
                code="invalid_team",
            )
        r = instance.robot_index(name)
        if r is None:
            raise DomainError(
                f"{where}.{j}.robot",
                f"unknown robot '{name}' (team of task {task.id!r}); the fleet has: "
                + ", ".join(robot.name for robot in robots),
                code="unknown_robot",
            )
        if r in seen:
            raise DomainError(
                f"{where}.{j}.robot",
                f"robot '{robots[r].name}' is already in this team ({where}.{seen[r]}); a "
                "team's members are distinct",
                code="invalid_team",
            )
        if not (instance.eligible[t, r] and covers(robots[r], feature)):
            raise DomainError(
                f"{where}.{j}.robot",
                f"robot '{robots[r].name}' cannot cover '{feature}' on task {task.id!r}: "
                + (
                    "it is not in its skills"
                    if robots[r].skills is not None
                    else "it does not rate it above 0"
                ),
                code="ineligible",
            )
        seen[r] = j
        given[feature].append(r)
    for feature, count in need.items():
        if len(given[feature]) != count:
            raise DomainError(
                where,
                f"task {task.id!r} needs {count} robot(s) for '{feature}' and the team gives "
                f"{len(given[feature])}; one entry per unit: {_needs(need)}",
                code="invalid_team",
            )
    return tuple(given[f].pop(0) for f in units_of(task))


def _needs(team: Mapping[str, int]) -> str:
    return ", ".join(f"{count} x '{feature}'" for feature, count in team.items())


def checked_pinned_teams(
    instance: Instance, pins: Mapping[int, int], teams: Mapping[int, Sequence[int]]
) -> dict[int, tuple[int, ...]]:
    """A pinned team is a pinned team task's whole team: one distinct robot per unit, its first
    member the pin's robot. Whether each member may still cover its unit is not asked: a pin is
    what was decided (and may be done), whatever `set_rates` says of the robot now."""
    out: dict[int, tuple[int, ...]] = {}
    for task, members in sorted(teams.items()):
        chosen = tuple(members)
        if task not in pins or not chosen or chosen[0] != pins[task]:
            raise DomainError(
                "pinned", f"the team pinned on task index {task} does not match its pin"
            )
        units = len(units_of(instance.tasks[task]))
        why = None
        if len(chosen) != units:
            why = f"{len(chosen)} members for {units} units; one robot per unit"
        elif len(set(chosen)) != len(chosen):
            why = "a robot covers two units; a team's members are distinct"
        if why is not None:
            raise DomainError(
                "pinned", f"the team pinned on task {instance.tasks[task].id!r} is invalid: {why}"
            )
        out[task] = chosen
    return out
