"""Test data: rows as the app would have written them, in one place."""

from __future__ import annotations

from typing import Any

from app.graph.recorder import DecisionRecord
from app.runs import records
from app.runs.lifecycle import status_writes
from app.store.models import Decision, Run


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


def decision_record(task_index: int = 0, **overrides: Any) -> DecisionRecord:
    """A task's final decision as the graph hands it to a recorder; tests that care about a
    value override it, the rest is whatever a valid decision needs."""
    fields: dict[str, Any] = {
        "task_id": task_index,
        "task_name": "t",
        "robot": 0,
        "robot_name": "a",
        "phase": "early",
        "expected_success": 0.5,
        "reasoning": "",
        "confidence": "High",
        "tradeoff": "",
        "quality": 1.0,
        "fallback": False,
        "attempts": 1,
        "failure_log": [],
        "loads_before": [0],
        "loads_after": [1],
        "balance_before": 0.0,
        "balance_after": 0.0,
        "severity_after": "low",
        **overrides,
    }
    return DecisionRecord(task_index=task_index, **fields)


def decision_row(run_id: str, task_index: int = 0, **overrides: Any) -> Decision:
    """A decisions row as the recorder stores decision_record(task_index, **overrides)."""
    return Decision(
        run_id=run_id, **records.decision_values(decision_record(task_index, **overrides))
    )
