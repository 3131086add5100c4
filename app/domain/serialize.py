"""Plain-JSON form of an instance, so a stored run can be rebuilt exactly on resume."""

from __future__ import annotations

from typing import Any

from app.domain.models import Instance, Robot, Task


def instance_to_dict(instance: Instance) -> dict[str, Any]:
    return {
        "tasks": [
            {"id": t.id, "name": t.name, "type": t.type, "features": list(t.features)}
            for t in instance.tasks
        ],
        "robots": [
            {
                "name": r.name,
                "label": r.label,
                "description": r.description,
                "success": dict(r.success),
            }
            for r in instance.robots
        ],
    }


def instance_from_dict(data: dict[str, Any]) -> Instance:
    return Instance(
        tasks=tuple(
            Task(
                id=t["id"],
                name=t["name"],
                type=t.get("type", "Custom"),
                features=tuple(t["features"]),
            )
            for t in data["tasks"]
        ),
        robots=tuple(
            Robot(
                name=r["name"],
                label=r.get("label", ""),
                description=r.get("description", ""),
                success=dict(r["success"]),
            )
            for r in data["robots"]
        ),
    )
