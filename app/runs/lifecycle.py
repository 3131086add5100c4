"""The only writer of a run's status: every move is checked against the transition table
(app.domain.lifecycle), stamps the run's times and writes its event in the caller's
transaction, so a status and the event that explains it commit together or not at all.

Run metrics (`ltaa_runs` by status) are read from the tables at scrape time, which stays
true across processes sharing PostgreSQL; a process-local counter here would not.
"""

from __future__ import annotations

from collections.abc import Iterator, Mapping
from contextlib import contextmanager
from typing import Any

from sqlalchemy import ColumnElement, update
from sqlalchemy.orm import Session

from app.domain.annotations import AnnotationKind
from app.domain.lifecycle import (
    FINISHED,
    EventKind,
    RunStatus,
    check_transition,
)
from app.store import repository as repo
from app.store.models import STATUS_WRITER, Run, RunAnnotation, RunEvent, utcnow
from app.webhooks.events import SIGNED_OFF
from app.webhooks.outbox import enqueue_for_event

__all__ = [
    "AnnotationKind",
    "EventKind",
    "RunStatus",
    "move",
    "move_where",
    "new_run",
    "record_annotation",
    "record_event",
    "status_writes",
]


@contextmanager
def status_writes() -> Iterator[None]:
    """Writing a run's status is allowed inside this (app.store.models' guards refuse it
    elsewhere). Only this module enters it, and test factories building rows."""
    token = STATUS_WRITER.set(True)
    try:
        yield
    finally:
        STATUS_WRITER.reset(token)


def record_event(
    session: Session, *, run_id: str, kind: EventKind, detail: Mapping[str, Any] | None = None
) -> RunEvent:
    """Append one event to the run's record (and its hash chain), in this transaction,
    with its webhook deliveries (the outbox: they commit with the event or not at all)."""
    event = repo.add_event(
        session=session, run_id=run_id, kind=EventKind(kind).value, detail=dict(detail or {})
    )
    enqueue_for_event(session, run_id=run_id, kind=event.kind, detail=event.detail, seq=event.seq)
    return event


def record_annotation(
    session: Session,
    *,
    run_id: str,
    kind: AnnotationKind,
    detail: Mapping[str, Any] | None = None,
    idempotency_key: str | None = None,
    request_digest: str | None = None,
) -> RunAnnotation:
    """Append one record about a run to its annotation chain (app.domain.annotations), in
    this transaction: what is said about a run after it finished, never a change to its
    decisions or events. A sign-off is also a `run.signed_off` webhook, from the outbox
    row written here."""
    annotation = repo.add_annotation(
        session=session,
        run_id=run_id,
        kind=AnnotationKind(kind).value,
        detail=dict(detail or {}),
        idempotency_key=idempotency_key,
        request_digest=request_digest,
    )
    if annotation.kind == AnnotationKind.SIGNOFF:
        enqueue_for_event(
            session,
            run_id=run_id,
            kind=SIGNED_OFF,
            detail=annotation.detail,
            seq=annotation.seq,
            annotation=True,
        )
    return annotation


def new_run(
    session: Session,
    *,
    run_id: str,
    created: Mapping[str, Any],
    first_event: EventKind = EventKind.CREATED,
    **fields: Any,
) -> Run:
    """A queued run and its first event: `created`, or `revised` for a revision
    (docs/living-plans.md#audit), whose detail is the link its chains are anchored to."""
    with status_writes():
        run = Run(id=run_id, status=RunStatus.QUEUED.value, **fields)
    session.add(run)
    session.flush()
    record_event(session, run_id=run_id, kind=first_event, detail=created)
    return run


def move(
    session: Session,
    run: Run,
    to: RunStatus,
    *,
    event: EventKind | None = None,
    detail: Mapping[str, Any] | None = None,
    error: str | None = None,
) -> None:
    """Move `run` to `to` (IllegalTransitionError if the table forbids it), set its error
    (cleared unless given) and finished time, and write `event` with `detail`."""
    check_transition(run.id, run.status, to)
    with status_writes():
        run.status = to.value
    run.error = error
    if to in FINISHED:
        run.finished_at = utcnow()
    if event is not None:
        record_event(session, run_id=run.id, kind=event, detail=detail)


def move_where(
    session: Session,
    *,
    run_id: str,
    current: RunStatus,
    to: RunStatus,
    where: tuple[ColumnElement[bool], ...] = (),
) -> bool:
    """Move one run from `current` to `to` only if it is still `current` and `where` holds,
    as one conditional UPDATE (no read first: concurrent processes race on the row, and
    exactly one wins). Writes no event; returns whether the run moved."""
    check_transition(run_id, current, to)
    stmt = (
        update(Run)
        .where(Run.id == run_id, Run.status == current.value, *where)
        .values(status=to.value)
        .returning(Run.id)
        .execution_options(synchronize_session=False)
    )
    with status_writes():
        return session.execute(stmt).first() is not None
