"""A run's audit record read in pages of bounded size, each in its own short session.

A 10,000-task run's prompts and replies are hundreds of megabytes, and a read transaction
held open for a slow download would keep SQLite's WAL from being checkpointed while runs
write. Rows are only ever appended in key order (and a re-upsert rewrites the same
content), so reading by key in pages sees a consistent prefix of a live run.
"""

from __future__ import annotations

from collections.abc import Callable, Iterator
from typing import Any, Protocol, TypeVar

from sqlalchemy.orm import Session, sessionmaker

from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.models import Attempt, Decision, Run, RunAnnotation, RunEvent
from app.store.tombstones import missing_run

DECISIONS_PER_PAGE = 100  # with their attempts' prompts: about 1-3 MB per page
EVENTS_PER_PAGE = 1000


def run_or_missing(session: Session, run_id: str) -> Run:
    run = repo.get_run(session=session, run_id=run_id)
    if run is None:
        raise missing_run(session, run_id)
    return run


class _Sequenced(Protocol):
    seq: Any


Row = TypeVar("Row", bound=_Sequenced)


def _seq_pages(
    sessions: sessionmaker[Session],
    read: Callable[[Session, int], list[Row]],
    last: int | None = None,
) -> Iterator[list[Row]]:
    """Pages of rows keyed by `seq`, each read in its own short session after the last;
    with `last`, only rows up to that seq (the prefix a snapshot saw: app.audit.snapshot)."""
    after = 0
    while True:
        with sessions() as session:
            page = read(session, after)
        if last is not None:
            page = [row for row in page if row.seq <= last]
        if not page:
            return
        yield page
        after = page[-1].seq


def event_pages(
    sessions: sessionmaker[Session], run_id: str, last: int | None = None
) -> Iterator[list[RunEvent]]:
    return _seq_pages(
        sessions,
        lambda session, after: repo.events_page(
            session=session, run_id=run_id, after_seq=after, limit=EVENTS_PER_PAGE
        ),
        last,
    )


def annotation_pages(
    sessions: sessionmaker[Session], run_id: str, last: int | None = None
) -> Iterator[list[RunAnnotation]]:
    return _seq_pages(
        sessions,
        lambda session, after: repo.annotations_page(
            session=session, run_id=run_id, after_seq=after, limit=EVENTS_PER_PAGE
        ),
        last,
    )


def chain_passes(
    revision_of: str | None, sequenced: bool = False
) -> tuple[tuple[bool | None, bool], ...]:
    """How to read a run's decisions in the order they were chained, as (pinned, by_seq)
    passes: all of them in task order, or a revision's pins first, then the rest
    (repo.revision_chain_order); a timed run's own decisions in the order the graph made
    them (`sequenced`, docs/schedules.md#the-chain-in-decision-order)."""
    if revision_of is None:
        return ((None, sequenced),)
    return ((True, False), (False, sequenced))


def decision_pages(
    sessions: sessionmaker[Session],
    run_id: str,
    pinned: bool | None = None,
    by_seq: bool = False,
    last: int | None = None,
) -> Iterator[list[tuple[Decision, list[Attempt]]]]:
    """`last`: only decisions up to that key (a seq when `by_seq`, else a task index), the
    prefix a snapshot saw (app.audit.snapshot); None: all, as many as there are by then."""

    def key(d: Decision) -> int:
        return (d.seq or 0) if by_seq else d.task_index

    after = -1
    while True:
        with sessions() as session:
            page = decision_repo.decisions_page(
                session=session,
                run_id=run_id,
                after_task=after,
                limit=DECISIONS_PER_PAGE,
                pinned=pinned,
                by_seq=by_seq,
            )
            if last is not None:
                page = [d for d in page if key(d) <= last]
            if not page:
                return
            tasks = [d.task_index for d in page]
            attempts = decision_repo.attempts_of_tasks(
                session=session, run_id=run_id, first=min(tasks), last=max(tasks)
            )
        yield [(d, attempts.get(d.task_index, [])) for d in page]
        after = key(page[-1])


def columns(row: Any, fields: dict[str, Any]) -> dict[str, Any]:
    return {name: getattr(row, name) for name in fields}
