"""Test data: rows as the app would have written them, in one place."""

from __future__ import annotations

from typing import Any

from app.store.models import Run, status_writes


def run_row(run_id: str, status: str = "queued", **overrides: Any) -> Run:
    """A runs row in any status, as a restored backup or an older release left it. Tests
    set up such rows directly; the app itself moves statuses only through
    app.runs.lifecycle."""
    fields: dict[str, Any] = {
        "request": {},
        "reasoner": "rules",
        "mode": "balanced",
        "n_tasks": 1,
        "n_robots": 1,
        "resumes": 0,
        "cancel_requested": False,
        **overrides,
    }
    with status_writes():
        return Run(id=run_id, status=status, **fields)
