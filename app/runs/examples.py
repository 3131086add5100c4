"""Example bodies of POST /runs, shown in /docs and sent by the schemathesis tests."""

from __future__ import annotations

from fastapi.openapi.models import Example

RUN_EXAMPLES: dict[str, Example] = {
    "baseline": Example(
        summary="Built-in scenario, offline rules reasoner",
        description="The paper's baseline fleet on the 36 TEACh tasks, balanced mode.",
        value={"scenario": "baseline", "mode": "balanced", "reasoner": "rules"},
    ),
    "capped": Example(
        summary="Explicit workload cap",
        value={"scenario": "heavy_excels", "mode": "aggressive_balance", "max_deviation": 1},
    ),
    "custom": Example(
        summary="Own tasks (TEACh keys) and robots",
        value={
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
            "robots": [
                {
                    "name": "arm",
                    "label": "Precision Arm",
                    "success": {"dexterous": 0.9, "heavy": 0.3},
                },
                {"name": "lifter", "label": "Lifter", "success": {"dexterous": 0.4, "heavy": 0.95}},
            ],
            "mode": "success_focused",
            "quality_threshold": 0.7,
            "max_retries": 2,
        },
    ),
}
