"""The durable recorder's held attempts (`defer_offline`): what a re-run would write again
identically waits for its decision's transaction; a reply that cost is written at once."""

from __future__ import annotations

from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import event
from sqlalchemy.orm import Session, sessionmaker

from app.audit.verify import verify_trace
from app.graph.recorder import AttemptRecord
from app.reasoners.attribution import REASONER, RULES
from app.reasoners.base import ReasonerReply
from app.runs import lifecycle
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.recorder import RunStop, RunSuperseded, SqlRecorder, status_fence
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import engine_of, make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from tests.support.factories import decision_record, run_row


@pytest.fixture
def sessions(tmp_path: Path) -> sessionmaker[Session]:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    factory = make_session_factory(make_engine(url))
    with transaction(factory) as session:
        session.add(run_row("r1", RunStatus.RUNNING.value, n_tasks=4))
    return factory


def _recorder(sessions: sessionmaker[Session]) -> SqlRecorder:
    stop = RunStop()
    return SqlRecorder(
        run_id="r1",
        sessions=sessions,
        stop=stop,
        fence=status_fence("r1", stop),
        defer_offline=True,
    )


def _prompt(t: int, attempt: int = 1) -> AttemptRecord:
    return AttemptRecord(
        task_index=t, attempt=attempt, tier=attempt - 1, system_prompt="s", user_prompt=f"u{t}"
    )


def _replied(t: int, reasoner: str, attempt: int = 1, **extra: Any) -> AttemptRecord:
    record = _prompt(t, attempt)
    model = None if reasoner == RULES else "model-x"
    record.reply = ReasonerReply(
        text="**Decision**: A", model=model, input_tokens=5, extra={REASONER: reasoner, **extra}
    )
    return record


def _stored(sessions: sessionmaker[Session]) -> tuple[list[tuple[int, int, bool]], list[int]]:
    with sessions() as session:
        attempts = [
            (a.task_index, a.attempt, a.reply_text is not None)
            for a in decision_repo.attempts(session=session, run_id="r1")
        ]
        decided = [d.task_index for d in decision_repo.decisions(session=session, run_id="r1")]
    return attempts, decided


def _commits(sessions: sessionmaker[Session]) -> list[int]:
    seen: list[int] = []
    event.listen(engine_of(sessions), "commit", lambda conn: seen.append(1))
    return seen


def test_rules_attempts_are_written_with_their_decision_in_one_transaction(
    sessions: sessionmaker[Session],
) -> None:
    recorder = _recorder(sessions)
    commits = _commits(sessions)
    for t in range(3):
        recorder.save_attempt(_prompt(t))  # build_prompt
        assert recorder.attempt(t, 1) is not None  # read back from what is held
        recorder.save_attempt(_replied(t, RULES))  # reason
        recorder.save_attempt(_replied(t, RULES))  # validate
        assert _stored(sessions) == ([(k, 1, True) for k in range(t)], list(range(t)))
        recorder.save_decision(decision_record(t, loads_after=[t + 1, 0]))
        assert _stored(sessions) == ([(k, 1, True) for k in range(t + 1)], list(range(t + 1)))
    assert len(commits) == 3
    assert verify_trace(sessions=sessions, run_id="r1").ok


def test_a_reply_that_cost_or_failed_is_written_at_once_with_what_was_held(
    sessions: sessionmaker[Session],
) -> None:
    recorder = _recorder(sessions)
    recorder.save_attempt(_prompt(0))
    assert _stored(sessions) == ([], [])
    recorder.save_attempt(_replied(0, "anthropic"))
    assert _stored(sessions) == ([(0, 1, True)], [])
    # Its validation (a re-run derives it again from the stored reply) waits.
    validated = _replied(0, "anthropic")
    validated.quality = 0.2
    recorder.save_attempt(validated)
    recorder.save_attempt(_prompt(0, 2))
    failed = _replied(0, RULES, 2, error="timed out")
    recorder.save_attempt(failed)
    assert _stored(sessions) == ([(0, 1, True), (0, 2, True)], [])
    with sessions() as session:
        first = decision_repo.get_attempt(session=session, run_id="r1", task_index=0, attempt=1)
        assert first is not None and first.quality == 0.2  # the held update went with it
    recorder.save_decision(decision_record(0, attempts=2, loads_after=[1, 0]))
    assert verify_trace(sessions=sessions, run_id="r1").ok


def test_after_a_restart_the_first_link_is_read_in_the_decisions_transaction(
    sessions: sessionmaker[Session],
) -> None:
    before = _recorder(sessions)
    before.save_attempt(_replied(0, RULES))
    before.save_decision(decision_record(0, loads_after=[1, 0]))
    before.save_attempt(_replied(1, RULES))  # held, then the process dies
    after = _recorder(sessions)  # the task is decided again from its start
    after.save_attempt(_replied(1, RULES))
    after.save_decision(decision_record(1, loads_after=[2, 0]))
    assert _stored(sessions) == ([(0, 1, True), (1, 1, True)], [0, 1])
    assert verify_trace(sessions=sessions, run_id="r1").ok


def test_a_superseded_run_stores_neither_the_held_attempts_nor_the_decision(
    sessions: sessionmaker[Session],
) -> None:
    recorder = _recorder(sessions)
    recorder.save_attempt(_replied(0, RULES))
    with transaction(sessions) as session:
        run = repo.get_run(session=session, run_id="r1")
        assert run is not None
        lifecycle.move(session, run, RunStatus.SUPERSEDED, event=EventKind.SUPERSEDED)
    with pytest.raises(RunSuperseded):
        recorder.save_decision(decision_record(0, loads_after=[1, 0]))
    assert _stored(sessions) == ([], [])
