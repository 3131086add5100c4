"""The parent's writes are fenced by its state (docs/living-plans.md#the-parent): once a revision
has superseded a run, a decision it was still computing is rolled back, never stored."""

from __future__ import annotations

from pathlib import Path

import pytest

from app.runs import lifecycle
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.recorder import RunStop, RunSuperseded, SqlRecorder, status_fence
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import make_engine, make_session_factory, transaction
from app.store.migrate import upgrade_head
from tests.support.factories import decision_record, run_row


def test_a_superseded_run_stores_nothing_more(tmp_path: Path) -> None:
    url = f"sqlite:///{tmp_path / 'app.db'}"
    upgrade_head(url)
    sessions = make_session_factory(make_engine(url))
    with transaction(sessions) as session:
        session.add(run_row("r1", RunStatus.RUNNING.value, n_tasks=3))
    stop = RunStop()
    # No stop flag is set here, as for a parent executing in another process: only the
    # fence inside the write's transaction can tell.
    recorder = SqlRecorder(
        run_id="r1", sessions=sessions, stop=stop, fence=status_fence("r1", stop)
    )
    recorder.save_decision(decision_record(0))
    with transaction(sessions) as session:
        run = repo.get_run(session=session, run_id="r1")
        assert run is not None
        lifecycle.move(session, run, RunStatus.SUPERSEDED, event=EventKind.SUPERSEDED)
    with pytest.raises(RunSuperseded):
        recorder.save_decision(decision_record(1))
    assert stop.superseded.is_set()
    with sessions() as session:
        assert [d.task_index for d in decision_repo.decisions(session=session, run_id="r1")] == [0]
    with pytest.raises(RunSuperseded):
        recorder.check_cancelled()
