"""The changes of a revision (docs/living-plans.md#changes), one handler per change type: each
checks its change against the draft revision and applies it, naming the request field of
any error.
"""

from __future__ import annotations

from collections.abc import Callable, Mapping, Sequence
from dataclasses import dataclass, field
from typing import Any

from app.domain.errors import DomainError
from app.domain.modes import Mode
from app.plans.revision_times import DELAY
from app.runs.spec import RunSpec

_TASK_TIME = ("duration", "after", "zone", "release", "deadline")


class ChangeType:
    ROBOT_UNAVAILABLE = "robot_unavailable"
    ROBOT_AVAILABLE = "robot_available"
    SET_RATES = "set_rates"
    ADD_ROBOT = "add_robot"
    ADD_TASKS = "add_tasks"
    REMOVE_TASKS = "remove_tasks"
    SET_MODE = "set_mode"
    DELAY = DELAY


def fleet_names(robots: Sequence[Mapping[str, Any]]) -> list[str]:
    return [str(r["name"]) for r in robots]


def _robot_index(robots: Sequence[Mapping[str, Any]], name: str, where: str) -> int:
    names = fleet_names(robots)
    if name not in names:
        raise DomainError(
            where, f"unknown robot '{name}'; the fleet is {', '.join(names)}", code="unknown_robot"
        )
    return names.index(name)


@dataclass
class Draft:
    """The revision as the changes build it: the fleet first, then the queue."""

    robots: list[dict[str, Any]]
    tasks: list[dict[str, Any]]
    unavailable: set[str]
    mode: Mode
    features: set[str]
    cap_from_change: tuple[bool, float | None] | None = None
    mode_changed: bool = False
    fleet_changes: list[dict[str, Any]] = field(default_factory=list)
    # Set once the pins are known; the queue changes read them.
    pinned_ids: set[str] = field(default_factory=set)
    known: set[str] = field(default_factory=set)
    removed: list[str] = field(default_factory=list)
    added_next: list[dict[str, Any]] = field(default_factory=list)
    added_end: list[dict[str, Any]] = field(default_factory=list)

    @classmethod
    def from_parent(cls, parent_spec: RunSpec) -> Draft:
        data = parent_spec.instance_data
        robots = [dict(r, success=dict(r["success"])) for r in data["robots"]]
        tasks = [dict(t) for t in data["tasks"]]
        parent_names = fleet_names(robots)
        return cls(
            robots=robots,
            tasks=tasks,
            unavailable={parent_names[i] for i in parent_spec.unavailable or []},
            mode=Mode(parent_spec.mode),
            features={f for t in tasks for f in t["features"]},
            known={str(t["id"]) for t in tasks},
        )


Handler = Callable[[Draft, int, Mapping[str, Any]], None]


def _robot_unavailable(d: Draft, i: int, c: Mapping[str, Any]) -> None:
    _robot_index(d.robots, c["robot"], f"changes.{i}.robot")
    d.unavailable.add(c["robot"])
    d.fleet_changes.append({"robot": c["robot"], "change": "unavailable"})


def _robot_available(d: Draft, i: int, c: Mapping[str, Any]) -> None:
    _robot_index(d.robots, c["robot"], f"changes.{i}.robot")
    d.unavailable.discard(c["robot"])
    d.fleet_changes.append({"robot": c["robot"], "change": "available"})


def _set_rates(d: Draft, i: int, c: Mapping[str, Any]) -> None:
    r = _robot_index(d.robots, c["robot"], f"changes.{i}.robot")
    rates = d.robots[r]["success"]
    for f in c["success"]:
        if f not in rates:
            raise DomainError(
                f"changes.{i}.success.{f}",
                f"robot '{c['robot']}' has no rate for feature '{f}'; it rates "
                f"{', '.join(sorted(rates))}",
                code="unknown_feature",
            )
    rates.update(c["success"])
    d.fleet_changes.append({"robot": c["robot"], "change": "rates", "success": c["success"]})


def _add_robot(d: Draft, i: int, c: Mapping[str, Any]) -> None:
    new = c["robot"]
    if new["name"] in fleet_names(d.robots):
        raise DomainError(
            f"changes.{i}.robot.name",
            f"robot '{new['name']}' is already in the fleet",
            code="duplicate_robot",
        )
    missing = sorted(d.features - set(new["success"]))
    if missing:
        raise DomainError(
            f"changes.{i}.robot.success",
            f"robot '{new['name']}' must rate every feature; missing {missing}",
            code="unknown_feature",
        )
    d.robots.append(
        {
            "name": new["name"],
            "label": new.get("label", ""),
            "description": new.get("description", ""),
            "success": dict(new["success"]),
        }
    )
    d.fleet_changes.append({"robot": new["name"], "change": "added"})


def _set_mode(d: Draft, i: int, c: Mapping[str, Any]) -> None:
    d.mode, d.mode_changed = Mode(c["mode"]), True
    if "max_deviation" in c:
        d.cap_from_change = (True, c["max_deviation"])


def _remove_tasks(d: Draft, i: int, c: Mapping[str, Any]) -> None:
    for j, task_id in enumerate(str(t) for t in c["task_ids"]):
        where = f"changes.{i}.task_ids.{j}"
        if task_id in d.pinned_ids:
            raise DomainError(
                where,
                f"task '{task_id}' is pinned (done or committed); a pinned task cannot be removed",
                code="pinned_task",
            )
        if task_id not in d.known or task_id in d.removed:
            raise DomainError(where, f"unknown task '{task_id}' in the queue", code="unknown_task")
        d.removed.append(task_id)


def _add_tasks(d: Draft, i: int, c: Mapping[str, Any]) -> None:
    for j, task in enumerate(c["tasks"]):
        task_id = str(task["id"])
        where = f"changes.{i}.tasks.{j}.id"
        if task_id in d.pinned_ids:
            raise DomainError(
                where, f"task '{task_id}' is pinned; it cannot be added again", code="pinned_task"
            )
        if task_id in d.known:
            raise DomainError(
                where, f"task id '{task_id}' is already in the queue", code="duplicate_task"
            )
        d.known.add(task_id)
        team = task.get("team")
        entry = {
            "id": task["id"],
            "name": task.get("name") or str(task["id"]),
            "type": task.get("type", "Custom"),
            # docs/living-plans.md#teams-in-a-revision: an added task may need a team; its
            # features are then its team's keys unless it names them.
            "features": list(task.get("features", team or [])),
            **({"team": dict(team)} if team else {}),
            # docs/living-plans.md#a-revision-in-time: an added task of a timed run brings its
            # own time fields.
            **{k: task[k] for k in _TASK_TIME if task.get(k) is not None},
        }
        (d.added_next if c.get("position", "end") == "next" else d.added_end).append(entry)


# One handler per change type, in two tables because the fleet comes first: which robots
# are unavailable decides what may stay pinned, and the pins decide what the queue changes
# may touch. A delay is neither: plan_times reads it from the changes.
FLEET_HANDLERS: dict[str, Handler] = {
    ChangeType.ROBOT_UNAVAILABLE: _robot_unavailable,
    ChangeType.ROBOT_AVAILABLE: _robot_available,
    ChangeType.SET_RATES: _set_rates,
    ChangeType.ADD_ROBOT: _add_robot,
    ChangeType.SET_MODE: _set_mode,
}
QUEUE_HANDLERS: dict[str, Handler] = {
    ChangeType.REMOVE_TASKS: _remove_tasks,
    ChangeType.ADD_TASKS: _add_tasks,
}


def apply_changes(
    d: Draft, changes: Sequence[Mapping[str, Any]], handlers: Mapping[str, Handler]
) -> None:
    for i, c in enumerate(changes):
        handler = handlers.get(c["type"])
        if handler is not None:
            handler(d, i, c)
