"""trace/verify on a run that is still writing judges one moment of it.

Verify reads a run's record in pages, each in its own short session, while a live run
keeps appending (a timed run still deciding, or a paused one whose in-flight decision
lands). A timed run's decisions are chained in decision order (`seq`), whose task indexes
are not consecutive: a decision appended between verify's first read and its pages was
reported as missing rows ("task_index 15 to 26 is missing"). Here the append happens
exactly between those reads, through the real store functions, on SQLite and PostgreSQL.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from contextlib import ExitStack
from pathlib import Path
from typing import Any

import pytest
from sqlalchemy import event
from sqlalchemy.orm import Session, sessionmaker

from app.audit.heads import chain_heads
from app.audit.verify import verify_trace
from app.runs import records
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import make_engine, transaction
from app.store.migrate import upgrade_head
from tests.support.factories import decision_record, run_row
from tests.support.postgres import fresh_database

RUN = "timed"
# The order the graph decided in (seq 0, 1, ...): not task order, as on a timed run.
DECIDED = (2, 0, 3, 1, 5, 4)


@pytest.fixture(params=["sqlite", "postgresql"])
def sessions(request: pytest.FixtureRequest, tmp_path: Path) -> Iterator[sessionmaker[Session]]:
    """A real database file / server: the race is between transactions, not in memory."""
    with ExitStack() as stack:
        url = (
            f"sqlite:///{tmp_path / 'ltaa.db'}"
            if request.param == "sqlite"
            else stack.enter_context(fresh_database())
        )
        upgrade_head(url)
        engine = make_engine(url)
        stack.callback(engine.dispose)
        yield sessionmaker(engine, expire_on_commit=False)


def _write(sessions: sessionmaker[Session], task: int, **columns: Any) -> None:
    """A decision with its event, written as a run writes them (chained by the store)."""
    values = records.decision_values(decision_record(task)) | columns
    with transaction(sessions) as session:
        decision_repo.upsert_decision(session=session, run_id=RUN, values=values)
        repo.add_event(session=session, run_id=RUN, kind="decided", detail={"task": task})


def _decide(sessions: sessionmaker[Session], seq: int) -> None:
    """The timed graph's seq-th decision."""
    _write(sessions, DECIDED[seq], seq=seq, start=10.0 * seq, end=10.0 * seq + 5, zone="A")


def _between_reads(write: Callable[[], None], sessions: sessionmaker[Session]) -> None:
    """`write` when verify opens its second session: after it has read what to verify,
    before it reads the decision pages (once: later sessions write nothing)."""
    opened = 0

    def after_begin(session: Session, *_: Any) -> None:
        nonlocal opened
        opened += 1
        if opened == 2:
            write()

    event.listen(sessions, "after_begin", after_begin)


def test_a_decision_appended_while_verifying_a_live_timed_run_is_not_a_gap(
    sessions: sessionmaker[Session],
) -> None:
    with transaction(sessions) as session:
        session.add(run_row(RUN, "running", mode="m", n_tasks=len(DECIDED), n_robots=1))
    for seq in range(3):
        _decide(sessions, seq)
    with sessions() as session:
        before = chain_heads(session, RUN)

    _between_reads(lambda: _decide(sessions, 3), sessions)
    report = verify_trace(sessions=sessions, run_id=RUN)

    assert report.first_break is None, report.first_break
    assert report.ok
    # The moment verify judged: the three decisions and their events, not the fourth.
    assert (report.decisions.rows, report.events.rows) == (3, 3)
    assert report.decisions.head == before.decision_hash
    assert report.events.head == before.event_hash

    # The hook wrote once; the next verify judges the later moment, and it verifies too.
    later = verify_trace(sessions=sessions, run_id=RUN)
    assert later.ok, later.first_break
    assert (later.decisions.rows, later.events.rows) == (4, 4)


def test_a_decision_appended_while_verifying_a_live_revision_is_not_a_gap(
    sessions: sessionmaker[Session],
) -> None:
    """An untimed revision is chained pins first, then the rest in task order: its order is
    read up front too, so a decision after a pin (task 4 after pinned task 3) appended
    between the reads was reported as task 3 missing."""
    with transaction(sessions) as session:
        session.add(
            run_row(RUN, "running", n_tasks=6, n_robots=1, revision_of="p", chain_anchor="a" * 64)
        )
    _write(sessions, 3, pinned=True, pinned_from="p")
    for task in (0, 1, 2):
        _write(sessions, task)
    with sessions() as session:
        before = chain_heads(session, RUN)

    _between_reads(lambda: _write(sessions, 4), sessions)
    report = verify_trace(sessions=sessions, run_id=RUN)

    # Not `ok`: there is no parent run here for the revision's link to be checked against.
    assert report.decisions.first_break is None, report.decisions.first_break
    assert report.events.first_break is None, report.events.first_break
    assert (report.decisions.rows, report.decisions.head) == (4, before.decision_hash)
    later = verify_trace(sessions=sessions, run_id=RUN)
    assert later.decisions.first_break is None, later.decisions.first_break
    assert later.decisions.rows == 5
