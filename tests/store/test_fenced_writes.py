"""Fenced writes (app.store.fenced): one statement that writes only while the run holds, and
the recorder's chain links computed from what it wrote, equal to the links read back."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import event
from sqlalchemy.orm import Session, sessionmaker

from app.audit.verify import verify_trace
from app.graph.recorder import AttemptRecord
from app.reasoners.base import ReasonerReply
from app.runs import lifecycle, records
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.recorder import RunStop, RunSuperseded, SqlRecorder, status_fence
from app.store import chain
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import engine_of, make_engine, make_session_factory, transaction
from app.store.fenced import WriteGuard, why_refused
from app.store.models import Attempt
from tests.support.factories import decision_record, run_row


@pytest.fixture
def sessions(tmp_path: Path) -> sessionmaker[Session]:
    from app.store.migrate import upgrade_head

    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    factory = make_session_factory(make_engine(url))
    with transaction(factory) as session:
        session.add(run_row("r1", RunStatus.RUNNING.value, n_tasks=4))
    return factory


def _supersede(sessions: sessionmaker[Session]) -> None:
    with transaction(sessions) as session:
        run = repo.get_run(session=session, run_id="r1")
        assert run is not None
        lifecycle.move(session, run, RunStatus.SUPERSEDED, event=EventKind.SUPERSEDED)


def _attempt(task_index: int, attempt: int = 1) -> AttemptRecord:
    return AttemptRecord(
        task_index=task_index,
        attempt=attempt,
        tier=attempt - 1,
        system_prompt="system",
        user_prompt=f"user {task_index}/{attempt}",
        reply=ReasonerReply(text="**Decision**: A", extra={"k": [1, 2.5]}),
        parsed={"robot": "A", "loads": [1, 0]},
        scores={"explanation": 1.0, "success_accuracy": 0.5},
        quality=0.75,
        accepted=attempt == 2,
        feedback=None if attempt == 2 else "too short",
    )


def test_a_fenced_upsert_writes_while_running_and_nothing_after_a_supersede(
    sessions: sessionmaker[Session],
) -> None:
    guard = WriteGuard(run_id="r1")
    values = records.attempt_values(_attempt(0))
    with engine_of(sessions).begin() as connection:
        first = decision_repo.write_attempt(
            connection=connection, run_id="r1", values=values, guard=guard
        )
        # The same key again is an update (an idempotent re-run), still one row.
        again = decision_repo.write_attempt(
            connection=connection, run_id="r1", values={**values, "quality": 0.5}, guard=guard
        )
    assert first.ok and again.ok
    _supersede(sessions)
    with engine_of(sessions).begin() as connection:
        refused = decision_repo.write_attempt(
            connection=connection,
            run_id="r1",
            values=records.attempt_values(_attempt(1)),
            guard=guard,
        )
        assert not refused.ok
        assert why_refused(connection, guard) == "status"
    with sessions() as session:
        rows = session.query(Attempt).filter_by(run_id="r1").all()
    assert [(a.task_index, a.quality) for a in rows] == [(0, 0.5)]


def test_a_lease_guard_refuses_a_process_that_does_not_hold_the_lease(
    sessions: sessionmaker[Session],
) -> None:
    guard = WriteGuard(run_id="r1", running=False, lease_owner="me", lease_s=30.0)
    with engine_of(sessions).begin() as connection:
        written = decision_repo.write_attempt(
            connection=connection,
            run_id="r1",
            values=records.attempt_values(_attempt(0)),
            guard=guard,
        )
        assert not written.ok
        assert why_refused(connection, guard) == "lease"


def test_the_recorder_refuses_after_a_supersede_and_sets_the_stop(
    sessions: sessionmaker[Session],
) -> None:
    stop = RunStop()
    recorder = SqlRecorder(
        run_id="r1", sessions=sessions, stop=stop, fence=status_fence("r1", stop)
    )
    recorder.save_attempt(_attempt(0))
    _supersede(sessions)
    with pytest.raises(RunSuperseded):
        recorder.save_attempt(_attempt(1))
    assert stop.superseded.is_set()
    assert recorder.attempt(1, 1) is None


def test_links_computed_from_the_writes_equal_the_links_read_from_the_table(
    sessions: sessionmaker[Session],
) -> None:
    stop = RunStop()
    recorder = SqlRecorder(
        run_id="r1", sessions=sessions, stop=stop, fence=status_fence("r1", stop)
    )
    statements: list[str] = []

    @event.listens_for(engine_of(sessions), "before_cursor_execute")
    def seen(conn: Any, cursor: Any, statement: str, *args: Any) -> None:
        statements.append(statement)

    for t in range(4):
        attempts = 2 if t % 2 else 1
        for a in range(1, attempts + 1):
            assert recorder.attempt(t, a) is None  # as build_prompt and retry ask first
            recorder.save_attempt(_attempt(t, a))
        record = decision_record(t, attempts=attempts, loads_after=[t + 1, 0])
        statements.clear()
        recorder.save_decision(record)
        # The first decision reads its link from the table; the next ones need no read.
        assert len(statements) == (1 if t else 4), statements
        # What the table gives for the same decision, now that its attempts are stored.
        with sessions() as session:
            stored = decision_repo.decisions(session=session, run_id="r1")[-1]
            prev = (
                chain.next_prev(
                    decision_repo.decisions(session=session, run_id="r1")[-2].chain_hash
                )
                if t
                else repo.chain_genesis(session=session, table="decisions", run_id="r1")
            )
            rows = [
                {name: getattr(row, name) for name in chain.ATTEMPT_FIELDS}
                for row in decision_repo.attempts_of_tasks(
                    session=session, run_id="r1", first=t, last=t
                )[t]
            ]
        expected = chain.decision_link(
            prev, chain.decision_columns(stored), chain.attempts_digest(rows)
        )
        assert stored.chain_hash == expected
    assert verify_trace(sessions=sessions, run_id="r1").ok
