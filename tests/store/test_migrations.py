"""The alembic migrations build exactly the tables the models describe."""

from __future__ import annotations

from collections.abc import Iterator
from contextlib import ExitStack
from pathlib import Path

import pytest
from alembic import command
from sqlalchemy import inspect
from sqlalchemy.exc import IntegrityError

from app.domain.models import MAX_NAME_CHARS
from app.runs import records
from app.store import decision_repository as decision_repo
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import alembic_config, upgrade_head
from tests.support.factories import decision_record, decision_row, run_row
from tests.support.postgres import fresh_database


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
    with transaction(sessions) as session:
        session.add(run_row("r1", "queued"))
        session.flush()
        session.add(decision_row("r1", 0))
    with pytest.raises(IntegrityError), transaction(sessions) as session:
        session.add(decision_row("r1", 0))


@pytest.fixture(params=["sqlite", "postgresql"])
def migrated_url(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[str]:
    with ExitStack() as stack:
        url = (
            f"sqlite:///{tmp_path / 'app.db'}"
            if request.param == "sqlite"
            else stack.enter_context(fresh_database())
        )
        upgrade_head(url)
        yield url


def test_the_longest_names_the_api_accepts_fit_the_columns(migrated_url: str) -> None:
    """PostgreSQL enforces VARCHAR lengths (SQLite does not): a run whose robot is named
    with the API's longest name must still be able to store its decisions."""
    longest = "x" * MAX_NAME_CHARS
    engine = make_engine(migrated_url)
    sessions = make_session_factory(engine)
    try:
        with transaction(sessions) as session:
            session.add(run_row("r1", "running"))
            session.flush()
            decision_repo.upsert_decision(
                session=session,
                run_id="r1",
                values=records.decision_values(
                    decision_record(
                        0, task_id=longest, task_name=longest, robot_name=longest, balance_after=1.0
                    )
                ),
            )
        with sessions() as session:
            stored = decision_repo.decisions(session=session, run_id="r1")[0]
            assert (stored.task_id, stored.robot_name) == (longest, longest)
    finally:
        engine.dispose()
