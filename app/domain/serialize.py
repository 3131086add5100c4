"""Plain-JSON form of an instance, so a stored run can be rebuilt exactly on resume.

The time fields of docs/schedules.md#the-model appear only when set, so an untimed instance's form
(and every hash computed over it) is exactly what it was before time existed.
"""

from __future__ import annotations

from collections.abc import Mapping
from datetime import datetime
from typing import Any

from app.domain.links import Link
from app.domain.models import Instance, Robot, Task
from app.domain.modes import Mode
from app.domain.objective import Objective, ObjectiveKind
from app.domain.problem import Problem

_TASK_TIME = ("duration", "after", "zone", "release", "deadline", "team")


def _task_dict(t: Task) -> dict[str, Any]:
    out: dict[str, Any] = {"id": t.id, "name": t.name, "type": t.type, "features": list(t.features)}
    for key in _TASK_TIME:
        value = getattr(t, key)
        if value is None or value == ():
            continue
        if isinstance(value, Mapping):
            value = dict(value)
        elif isinstance(value, tuple):
            value = [v.to_dict() if isinstance(v, Link) else v for v in value]
        out[key] = value
    return out


def _robot_dict(r: Robot) -> dict[str, Any]:
    out: dict[str, Any] = {
        "name": r.name,
        "label": r.label,
        "description": r.description,
        "success": dict(r.success),
    }
    if r.zone is not None:
        out["zone"] = r.zone
    if r.available is not None:
        out["available"] = list(r.available)
    if r.skills is not None:  # docs/allocation.md#teams; absent keeps older forms unchanged
        out["skills"] = list(r.skills)
    return out


def instance_to_dict(instance: Instance) -> dict[str, Any]:
    out: dict[str, Any] = {
        "tasks": [_task_dict(t) for t in instance.tasks],
        "robots": [_robot_dict(r) for r in instance.robots],
    }
    if instance.travel is not None:
        out["travel"] = {a: dict(row) for a, row in instance.travel.items()}
    if instance.start is not None:
        out["start"] = instance.start.isoformat()
    return out


def _duration(value: Any) -> Any:
    return dict(value) if isinstance(value, Mapping) else value


def _after(entry: Any) -> Any:
    """A link object as a Link (checked with the instance); a plain id as it is."""
    if isinstance(entry, Mapping) and set(entry) <= {"task", "type", "lag"} and "task" in entry:
        return Link(entry["task"], entry.get("type", "FS"), entry.get("lag", 0))
    return entry


def instance_from_dict(data: dict[str, Any]) -> Instance:
    start = data.get("start")
    available = [r.get("available") for r in data["robots"]]
    return Instance(
        tasks=tuple(
            Task(
                id=t["id"],
                name=t["name"],
                type=t.get("type", "Custom"),
                features=tuple(t["features"]),
                duration=_duration(t.get("duration")),
                after=tuple(_after(a) for a in t.get("after", ())),
                zone=t.get("zone"),
                release=t.get("release"),
                deadline=t.get("deadline"),
                team=t.get("team"),
            )
            for t in data["tasks"]
        ),
        robots=tuple(
            Robot(
                name=r["name"],
                label=r.get("label", ""),
                description=r.get("description", ""),
                success=dict(r["success"]),
                zone=r.get("zone"),
                available=None if shift is None else (shift[0], shift[1]),
                skills=None if r.get("skills") is None else tuple(r["skills"]),
            )
            for r, shift in zip(data["robots"], available, strict=True)
        ),
        travel=data.get("travel"),
        start=None if start is None else datetime.fromisoformat(start),
    )


def problem_from_dict(
    data: dict[str, Any],
    mode: str,
    max_deviation: float | None,
    *,
    objective: str,
    min_expected_success: float,
    **build: Any,
) -> Problem:
    """The problem a stored run poses (app.runs.spec.RunSpec.problem, on every start and
    resume), in one call: its instance's plain-JSON form read back, its mode and objective
    (docs/schedules.md#the-model; Problem.build refuses any but the default untimed) named
    by value, the rest of Problem.build's arguments as given."""
    return Problem.build(
        instance_from_dict(data),
        Mode(mode),
        max_deviation,
        objective=Objective(ObjectiveKind(objective), min_expected_success),
        **build,
    )
