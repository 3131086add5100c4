"""The built-in data: the 36 TEACh actions and the four robot scenarios."""

from __future__ import annotations

import json
from dataclasses import dataclass
from functools import cache
from importlib import resources
from typing import Any

from app.domain.errors import DomainError
from app.domain.models import Instance, Robot, Task


def _load(name: str) -> Any:
    return json.loads(resources.files("app.data").joinpath(name).read_text(encoding="utf-8"))


@cache
def teach_tasks() -> tuple[Task, ...]:
    return tuple(
        Task(
            id=a["action_id"],
            name=a["action_name"],
            type=a["action_type"],
            features=tuple(a["features"]),
        )
        for a in _load("teach_actions.json")["actions"]
    )


@dataclass(frozen=True)
class Scenario:
    name: str
    description: str
    instance: Instance


@cache
def scenarios() -> dict[str, Scenario]:
    doc = _load("scenarios.json")
    meta = {r["name"]: r for r in doc["robots"]}
    out: dict[str, Scenario] = {}
    for sc in doc["scenarios"]:
        robots = tuple(
            Robot(
                name=name,
                label=meta[name]["label"],
                description=meta[name]["description"],
                success=dict(rates),
            )
            for name, rates in sc["success"].items()
        )
        out[sc["name"]] = Scenario(
            sc["name"], sc["description"], Instance(tasks=teach_tasks(), robots=robots)
        )
    return out


def scenario(name: str) -> Scenario:
    try:
        return scenarios()[name]
    except KeyError:
        known = ", ".join(scenarios())
        raise DomainError(
            "scenario",
            f"unknown scenario '{name}'; choose one of: {known}",
            code="unknown_scenario",
        ) from None
