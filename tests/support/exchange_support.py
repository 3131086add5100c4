"""The small site project both formats are checked with, written by MPXJ (tests only)."""

from __future__ import annotations

from datetime import datetime
from functools import cache
from typing import Any

from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.list_schedule import list_schedule
from app.domain.scheduling.schedule import Schedule
from app.domain.serialize import instance_from_dict
from app.exchange import Draft
from tests.support.mpxj_oracle import Spec, build_project, write

START = datetime(2026, 3, 2, 8, 0)


def site() -> list[Spec]:
    """All four link types with lags (a lead too), a milestone between two tasks, a task
    with two resources and one feature, constraints, a task without features."""
    return [
        Spec("Formwork", 8, "lift", ("Crane",), release=datetime(2026, 3, 2, 9, 0)),
        Spec("Pour", 4, "pour, heavy", ("Pump",), links=(("Formwork", "FS", 30),)),
        Spec("Screed", 3, "screed", ("Screeder",), links=(("Pour", "SS", 20),)),
        Spec("Trowel", 2, "screed", ("Screeder",), links=(("Screed", "FF", -15),)),
        Spec(
            "Inspect",
            1,
            "scan",
            ("Scanner",),
            links=(("Trowel", "SF", 60),),
            finish_by=datetime(2026, 3, 3, 17, 0),
        ),
        Spec("Slab ready", 0, milestone=True, links=(("Inspect", "FS", 5),)),
        Spec("Strip", 2.5, "lift", ("Crane",), links=(("Slab ready", "FS", 10),)),
        Spec("Lift rebar", 2, "lift", ("Crane", "Hoist"), links=(("Formwork", "SS", 0),)),
        Spec("Sweep", 1, None, ("Crane",), links=(("Strip", "FS", 0),)),
    ]


@cache
def files() -> dict[str, bytes]:
    project = build_project("Level 2 slab", START, site())
    return {fmt: write(project, fmt) for fmt in ("mspdi", "xer")}


def plan_of(draft: Draft) -> tuple[Problem, Schedule]:
    """A plan of a draft as a caller would make it: rates filled in, each task on the robots
    the file assigned it (a team task on all of them, docs/allocation.md#teams), its typed
    links honoured (docs/schedules.md#links)."""
    features = sorted({f for t in draft.tasks for f in t["features"]})
    request: dict[str, Any] = {
        "tasks": draft.tasks,
        "robots": [{**r, "success": dict.fromkeys(features, 0.9)} for r in draft.robots],
        "start": draft.start,
    }
    problem = Problem.build(instance_from_dict(request), Mode.BALANCED, uncapped=True)
    names = [r["name"] for r in draft.robots]
    assignment = [names.index(t["planned_robots"][0]) for t in draft.tasks]
    teams = {
        i: tuple(names.index(n) for n in t["planned_robots"])
        for i, t in enumerate(draft.tasks)
        if t.get("team")
    }
    return problem, list_schedule(problem, assignment, teams)
