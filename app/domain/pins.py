"""Pins and unavailable robots as a request names them (task ids, robot names) -> indexes.

The domain's Problem takes indexes; requests name tasks by id and robots by name (or
label). Every error names the offending entry by its dotted path in the request.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass

from app.domain.errors import DomainError
from app.domain.models import Instance, TaskId
from app.domain.teams import units_of


@dataclass(frozen=True)
class Pins:
    pinned: dict[int, int]  # task index -> robot index
    unavailable: frozenset[int]


def resolve_pins(
    instance: Instance,
    pinned: Sequence[tuple[TaskId, str]],
    unavailable: Sequence[str],
    *,
    pinned_field: str = "pinned",
    unavailable_field: str = "unavailable",
) -> Pins:
    # Task ids are unique as text (validate_instance), so 10 and "10" name the same task.
    task_at = {str(task.id): t for t, task in enumerate(instance.tasks)}
    known_robots = ", ".join(r.name for r in instance.robots)
    pins: dict[int, int] = {}
    pinned_by: dict[int, int] = {}
    for i, (task_id, robot_name) in enumerate(pinned):
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
        r = instance.robot_index(robot_name)
        if r is None:
            raise DomainError(
                f"{pinned_field}.{i}.robot",
                f"unknown robot '{robot_name}' (pin of task {task_id!r}); the fleet has: "
                f"{known_robots}",
                code="unknown_robot",
            )
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
    return Pins(pinned=pins, unavailable=frozenset(off))


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
