"""Small MSPDI files written by our own writer, for tests that run without Java (the
browser, the CLI, end-to-end servers); the MPXJ-written ones are in tests/exchange_support.

The robots are the paper's (light, medium, heavy) so a site of baseline runs has learned
rates for them (tests/support/site_support.py).
"""

from __future__ import annotations

from datetime import UTC, datetime
from typing import Any

from app.domain.modes import Mode
from app.domain.problem import Problem
from app.domain.scheduling.list_schedule import list_schedule
from app.domain.serialize import instance_from_dict
from app.exchange import write_mspdi

START = datetime(2026, 3, 2, 8, 0, tzinfo=UTC)
TASKS: list[dict[str, Any]] = [
    {"id": 1, "name": "Carry boards", "features": ["heavy"], "duration": 60},
    {"id": 2, "name": "Fit panels", "features": ["careful"], "duration": 45, "after": [1]},
    {
        "id": 3,
        "name": "Seal joints",
        "features": ["careful", "dexterous"],
        "duration": 30,
        "after": [2],
    },
]
ROBOTS = ["heavy", "light"]
# A start-to-start link with a lag (docs/schedules.md#links): task 2 starts 20 min after 1 does.
TYPED_AFTER: list[Any] = [{"task": 1, "type": "SS", "lag": 20}]


def small_mspdi(*, typed: bool = False, name: str = "Level 3 fit-out") -> bytes:
    """Three tasks in a chain, planned on heavy then light; `typed`: the second link a
    start-to-start with a 20-minute lag."""
    tasks = [dict(t) for t in TASKS]
    if typed:
        tasks[1]["after"] = TYPED_AFTER
    request = {
        "tasks": tasks,
        "robots": [
            {"name": r, "success": {"heavy": 0.9, "careful": 0.9, "dexterous": 0.9}} for r in ROBOTS
        ],
        "start": START.isoformat(),
    }
    problem = Problem.build(instance_from_dict(request), Mode.BALANCED, uncapped=True)
    schedule = list_schedule(problem, [0, 1, 1])
    return write_mspdi(problem, schedule, project_name=name)
