"""The alembic migrations build exactly the tables the models describe."""

from __future__ import annotations

from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import inspect
from sqlalchemy.exc import IntegrityError

from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import alembic_config, upgrade_head
from app.store.models import Decision, Run


def test_upgrade_head_matches_the_models(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    command.check(alembic_config(url))  # raises if models and migrations differ
    tables = set(inspect(make_engine(url)).get_table_names())
    assert {"runs", "run_events", "decisions", "attempts"} <= tables


def test_one_decision_per_run_and_task_is_enforced(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    sessions = make_session_factory(make_engine(url))
    row = {"task_id": "0", "task_name": "t", "robot": 0, "robot_name": "a", "phase": "early",
           "expected_success": 0.5, "reasoning": "", "confidence": "High", "tradeoff": "",
           "quality": 1.0, "fallback": False, "attempts": 1, "failure_log": [],
           "loads_before": [0], "loads_after": [1], "balance_before": 0.0,
           "balance_after": 0.0, "severity_after": "low"}
    with transaction(sessions) as session:
        session.add(Run(id="r1", status="queued", request={}, reasoner="rules", mode="balanced",
                        n_tasks=1, n_robots=1, resumes=0, cancel_requested=False))
        session.flush()
        session.add(Decision(run_id="r1", task_index=0, **row))
    with pytest.raises(IntegrityError), transaction(sessions) as session:
        session.add(Decision(run_id="r1", task_index=0, **row))
