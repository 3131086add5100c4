"""The built-in data: the 36 TEACh actions, the four robot scenarios, and the timed
scenarios of docs/schedules.md#where-the-numbers-of-baseline_timed-come-from (kept apart:
`scenarios()` lists exactly the four untimed ones that `GET /scenarios` serves; a later phase
decides how the API offers the timed ones)."""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass, replace
from datetime import datetime
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


@cache
def timed_scenarios() -> dict[str, Scenario]:
    """The timed variants (`baseline_timed`): the 36 TEACh tasks with durations per robot,
    zones, precedence, releases and deadlines, the robots with start zones and shifts.
    Where each number comes from: docs/schedules.md."""
    out: dict[str, Scenario] = {}
    for sc in _load("timed_scenarios.json")["scenarios"]:
        if "based_on" in sc:  # a variant of a timed scenario listed before it
            out[sc["name"]] = _team_variant(sc, out[sc["based_on"]].instance)
            continue
        base = scenarios()[sc["success_from"]].instance
        timing = {str(t["id"]): t for t in sc["tasks"]}
        tasks = tuple(
            replace(
                task,
                duration=dict(timing[str(task.id)]["duration"]),
                zone=timing[str(task.id)]["zone"],
                after=tuple(timing[str(task.id)].get("after", ())),
                release=timing[str(task.id)].get("release"),
                deadline=timing[str(task.id)].get("deadline"),
            )
            for task in base.tasks
        )
        robots = tuple(
            replace(
                robot,
                zone=sc["robots"][robot.name]["zone"],
                available=tuple(sc["robots"][robot.name]["available"]),
            )
            for robot in base.robots
        )
        instance = Instance(
            tasks=tasks,
            robots=robots,
            travel=sc["travel"],
            start=datetime.fromisoformat(sc["start"]),
        )
        out[sc["name"]] = Scenario(sc["name"], sc["description"], instance)
    return out


def _team_variant(sc: dict[str, Any], base: Instance) -> Scenario:
    """`baseline_team` (docs/schedules.md#the-team-scenario): the timed scenario it is based
    on, where the tasks listed under `teams` need several robots at once, each busy for the
    reference minutes of the task's type (`team_duration_rule`)."""
    teams = {str(entry["id"]): dict(entry["team"]) for entry in sc["teams"]}
    listed = _load("timed_scenarios.json")["scenarios"]
    rule = next(other["duration_rule"] for other in listed if other["name"] == sc["based_on"])
    minutes = rule["base_minutes"]
    tasks = tuple(
        replace(task, team=teams[str(task.id)], duration=float(minutes[task.type]))
        if str(task.id) in teams
        else task
        for task in base.tasks
    )
    instance = Instance(tasks=tasks, robots=base.robots, travel=base.travel, start=base.start)
    return Scenario(sc["name"], sc["description"], instance)


def timed_scenario(name: str) -> Scenario:
    try:
        return timed_scenarios()[name]
    except KeyError:
        known = ", ".join(timed_scenarios())
        raise DomainError(
            "scenario",
            f"unknown timed scenario '{name}'; choose one of: {known}",
            code="unknown_scenario",
        ) from None


_FORMS = "send either a built-in 'scenario' (see GET /scenarios) or your own 'tasks' and 'robots'"


def instance_of(
    scenario_name: str | None,
    tasks: Sequence[Task] | None,
    robots: Sequence[Robot] | None,
    *,
    travel: Mapping[str, Mapping[str, float]] | None = None,
    start: datetime | None = None,
    arrival: datetime | None = None,
) -> Instance:
    """The instance a request describes, by a built-in scenario's name or by its own tasks
    and robots (with, for a timed instance, its travel times and start); DomainError naming
    the field if it describes none, or both. Timed tasks of its own sent without `start`
    start at the request's `arrival` (docs/api.md#plans-in-time)."""
    custom = tasks is not None or robots is not None
    if scenario_name is not None:
        if custom:
            raise DomainError(
                "scenario",
                f"'scenario' was sent together with 'tasks'/'robots'; {_FORMS}, not both",
                code="conflicting_fields",
            )
        timed = scenario_name in timed_scenarios()
        for name, value in (("travel", travel), ("start", start)):
            if value is not None:
                own = (
                    f"the built-in scenario {scenario_name!r} has its own"
                    if timed
                    else "the built-in scenario is untimed"
                )
                raise DomainError(
                    name,
                    f"'{name}' times your own tasks; {own}, send 'tasks' and 'robots' with "
                    "durations instead",
                    code="conflicting_fields",
                )
        if timed:
            return timed_scenario(scenario_name).instance
        return scenario(scenario_name).instance
    if tasks is None:
        raise DomainError(
            "tasks" if custom else "scenario",
            f"{'tasks missing' if custom else 'no instance given'}; {_FORMS}",
            code="missing",
        )
    if robots is None:
        raise DomainError("robots", f"robots missing; {_FORMS}", code="missing")
    if start is None and any(t.duration is not None for t in tasks):
        start = arrival
    return Instance(tasks=tuple(tasks), robots=tuple(robots), travel=travel, start=start)
