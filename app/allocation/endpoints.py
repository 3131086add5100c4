"""POST /allocate: solve one allocation synchronously with a named solver."""

from __future__ import annotations

from typing import Annotated, Any

from fastapi import APIRouter, Body
from fastapi.concurrency import run_in_threadpool
from fastapi.openapi.models import Example

from app.allocation.schemas import AllocateRequest, AllocateResponse
from app.allocation.service import allocate as run_allocation
from app.http.deps import ClientDep, SettingsDep
from app.http.responses import BODY, CLIENT, errors

router = APIRouter(tags=["allocate"])

_CUSTOM_ROBOTS: list[dict[str, Any]] = [
    {"name": "arm", "label": "Precision Arm", "success": {"dexterous": 0.9, "heavy": 0.3}},
    {"name": "lifter", "label": "Lifter", "success": {"dexterous": 0.4, "heavy": 0.95}},
]

EXAMPLES: dict[str, Example] = {
    "baseline": Example(
        summary="Built-in scenario, exact DP",
        description="The paper's baseline fleet on the 36 TEACh tasks, balanced mode "
        "(default cap ceil(W/3) = 4).",
        value={"solver": "dp", "scenario": "baseline", "mode": "balanced"},
    ),
    "capped": Example(
        summary="Explicit workload cap",
        value={
            "solver": "optimal",
            "scenario": "heavy_excels",
            "mode": "aggressive_balance",
            "max_deviation": 1,
        },
    ),
    "custom": Example(
        summary="Own tasks (TEACh keys) and robots",
        value={
            "solver": "greedy",
            "tasks": [
                {
                    "action_id": 200,
                    "action_name": "Pickup",
                    "action_type": "ObjectInteraction",
                    "features": ["heavy"],
                },
                {"id": "weld-7", "name": "Weld seam", "features": ["dexterous"]},
                {"id": "lift-2", "name": "Lift beam", "features": ["heavy", "dexterous"]},
            ],
            "robots": _CUSTOM_ROBOTS,
            "mode": "success_focused",
            "seed": 7,
        },
    ),
    "timed": Example(
        summary="Timed instance, exact schedule (docs/api.md#plans-in-time)",
        description="Durations (one number, or per robot), precedence (`after`), zones with "
        "travel minutes between them, a release, a deadline and shifts. The answer carries "
        "a `schedule` block; `schedule` proves its makespan (`status`, `bound`, `gap`), any "
        "other solver's assignment is timed by the list scheduler.",
        value={
            "solver": "schedule",
            "tasks": [
                {
                    "id": "form-1",
                    "name": "Formwork",
                    "features": ["heavy"],
                    "duration": 40,
                    "zone": "A",
                },
                {
                    "id": "rebar-1",
                    "name": "Rebar",
                    "features": ["heavy", "dexterous"],
                    "duration": {"arm": 50, "lifter": 35},
                    "zone": "A",
                    "after": ["form-1"],
                },
                {
                    "id": "pour-1",
                    "name": "Pour",
                    "features": ["heavy"],
                    "duration": 25,
                    "zone": "B",
                    "after": ["rebar-1"],
                    "release": 60,
                },
                {
                    "id": "check-1",
                    "name": "Inspect",
                    "features": ["dexterous"],
                    "duration": 15,
                    "zone": "B",
                    "after": ["pour-1"],
                    "deadline": 240,
                },
            ],
            "robots": [
                {**_CUSTOM_ROBOTS[0], "zone": "A", "available": [0, 480]},
                {**_CUSTOM_ROBOTS[1], "zone": "B", "available": [30, 450]},
            ],
            "travel": {"A": {"B": 6}},
            "start": "2026-03-02T07:00:00+01:00",
            "mode": "success_focused",
            "options": {"time_limit_s": 5},
        },
    ),
    "q_learning": Example(
        summary="Approximate solver with options",
        value={
            "solver": "q_learning",
            "scenario": "baseline",
            "seed": 1,
            "options": {"episodes": 2000},
        },
    ),
}


@router.post("/allocate", response_model=AllocateResponse, responses=errors(*CLIENT, *BODY, 502))
async def allocate(
    caller: ClientDep,
    body: Annotated[AllocateRequest, Body(openapi_examples=EXAMPLES)],
    settings: SettingsDep,
) -> AllocateResponse:
    """Allocate every task to a robot with the chosen solver, respecting the workload cap."""
    # Solving is CPU-bound, so it goes to the threadpool (the event loop stays free for
    # health checks and run status) as ONE job. A plain `def` route would queue the solve
    # and the response's validation as separate first-come jobs: under a burst, every
    # response then waited for every solve sent before it, even a 3 ms greedy one.
    return await run_in_threadpool(run_allocation, body, settings)
