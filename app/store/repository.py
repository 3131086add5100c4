"""Keyword-only data access for the app tables. Writes are upserts keyed by the natural
keys, so a node that LangGraph re-executes after a crash rewrites, never duplicates."""

from __future__ import annotations

from collections.abc import Callable, Sequence
from typing import Any

from sqlalchemy import (
    select,
    text,
    update,
)
from sqlalchemy.orm import Session

from app.domain.lifecycle import RunStatus
from app.store import chain
from app.store.models import (
    ExecutionReport,
    RequestKey,
    Run,
    RunAnnotation,
    RunEvent,
    RunSignature,
)


def get_run(*, session: Session, run_id: str, for_update: bool = False) -> Run | None:
    """`for_update` makes the row read current until the transaction ends: PostgreSQL locks
    it (FOR UPDATE); SQLite, which has no row locks, takes the database's write lock first.
    Without that, SQLite reads the row before the transaction writes anything, and a
    writer that commits in between (a review resolution queueing the run a cancel read as
    awaiting review) is overwritten by a decision made on the stale status."""
    if for_update and session.get_bind().dialect.name == "sqlite":
        # A write that changes nothing: the transaction begins here, holding the write
        # lock (waiting up to the busy timeout for it), so the read below is current.
        # (n_tasks never changes; the key is not rewritten, which would check the children.)
        session.execute(text("UPDATE runs SET n_tasks = n_tasks WHERE id = :id"), {"id": run_id})
    return session.get(
        Run, run_id, with_for_update=for_update or None, populate_existing=for_update
    )


def list_runs(
    *, session: Session, status: str | None, limit: int, offset: int, site: str | None = None
) -> list[Run]:
    query = select(Run).order_by(Run.created_at.desc(), Run.id)
    if status:
        query = query.where(Run.status == status)
    if site is not None:
        query = query.where(Run.site == site)
    return list(session.scalars(query.limit(limit).offset(offset)))


def runs_with_status(*, session: Session, statuses: Sequence[str]) -> list[Run]:
    return list(session.scalars(select(Run).where(Run.status.in_(statuses)).order_by(Run.id)))


def chain_genesis(*, session: Session, table: chain.Table, run_id: str) -> str:
    """The genesis of a run's chain, by the run's scheme (one primary-key read; only the
    first row of a chain needs it)."""
    run = session.get(Run, run_id)
    if run is None:
        return chain.genesis(table, run_id)
    return chain.run_genesis(
        table,
        run_id,
        scheme=run.chain_scheme,
        request=run.request,
        mode=run.mode,
        max_deviation=run.max_deviation,
        anchor=run.chain_anchor,
    )


def signatures(*, session: Session, run_id: str) -> list[RunSignature]:
    return list(
        session.scalars(
            select(RunSignature).where(RunSignature.run_id == run_id).order_by(RunSignature.id)
        )
    )


def latest_signature(*, session: Session, run_id: str) -> RunSignature | None:
    return session.scalars(
        select(RunSignature)
        .where(RunSignature.run_id == run_id)
        .order_by(RunSignature.id.desc())
        .limit(1)
    ).first()


def _append_point(
    session: Session,
    model: type[RunEvent] | type[RunAnnotation],
    run_id: str,
    first_prev: Callable[[], str],
) -> tuple[int, str]:
    """Where a run's event or annotation chain goes on: the next seq and the link the new row
    hangs off, from one indexed lookup (the chain's genesis before the first row)."""
    last = session.execute(
        select(model.seq, model.chain_hash)
        .where(model.run_id == run_id)
        .order_by(model.seq.desc())
        .limit(1)
    ).first()
    if last is None:
        return 1, first_prev()
    return last.seq + 1, chain.next_prev(last.chain_hash)


def add_event(*, session: Session, run_id: str, kind: str, detail: dict[str, Any]) -> RunEvent:
    seq, prev = _append_point(
        session,
        RunEvent,
        run_id,
        lambda: chain_genesis(session=session, table="events", run_id=run_id),
    )
    link = chain.event_link(prev, {"seq": seq, "kind": kind, "detail": detail})
    event = RunEvent(run_id=run_id, seq=seq, kind=kind, detail=detail, chain_hash=link)
    session.add(event)
    return event


def add_annotation(
    *,
    session: Session,
    run_id: str,
    kind: str,
    detail: dict[str, Any],
    idempotency_key: str | None = None,
    request_digest: str | None = None,
) -> RunAnnotation:
    """Append to the run's annotation chain. Two writers at once collide on (run_id, seq)
    and one rolls back: lock the run row first where that matters."""
    seq, prev = _append_point(
        session, RunAnnotation, run_id, lambda: chain.genesis("annotations", run_id)
    )
    link = chain.annotation_link(prev, {"seq": seq, "kind": kind, "detail": detail})
    row = RunAnnotation(
        run_id=run_id,
        seq=seq,
        kind=kind,
        detail=detail,
        chain_hash=link,
        idempotency_key=idempotency_key,
        request_digest=request_digest,
    )
    session.add(row)
    session.flush()
    return row


def annotations_page(
    *, session: Session, run_id: str, kind: str | None = None, after_seq: int = 0, limit: int = 1000
) -> list[RunAnnotation]:
    query = select(RunAnnotation).where(
        RunAnnotation.run_id == run_id, RunAnnotation.seq > after_seq
    )
    if kind is not None:
        query = query.where(RunAnnotation.kind == kind)
    return list(session.scalars(query.order_by(RunAnnotation.seq).limit(limit)))


def annotation_for_key(*, session: Session, idempotency_key: str) -> RunAnnotation | None:
    return session.scalar(
        select(RunAnnotation).where(RunAnnotation.idempotency_key == idempotency_key)
    )


def still_running(*, session: Session, run_id: str) -> bool:
    """Write-lock the run's row if it is still running (a conditional UPDATE that changes
    nothing), else False: the fence of every recorder write."""
    stmt = (
        update(Run)
        .where(Run.id == run_id, Run.status == RunStatus.RUNNING.value)
        .values(updated_at=Run.updated_at)
        .returning(Run.id)
        .execution_options(synchronize_session=False)
    )
    return session.execute(stmt).first() is not None


def chain_anchor(*, session: Session, run_id: str) -> str | None:
    """A revision's link to its parent that its chains start from (None: not a revision)."""
    return session.scalar(select(Run.chain_anchor).where(Run.id == run_id))


def events_page(*, session: Session, run_id: str, after_seq: int, limit: int) -> list[RunEvent]:
    """Events with seq > after_seq, in order: the audit record read in bounded pages."""
    return list(
        session.scalars(
            select(RunEvent)
            .where(RunEvent.run_id == run_id, RunEvent.seq > after_seq)
            .order_by(RunEvent.seq)
            .limit(limit)
        )
    )


def events(*, session: Session, run_id: str) -> list[RunEvent]:
    return list(
        session.scalars(select(RunEvent).where(RunEvent.run_id == run_id).order_by(RunEvent.seq))
    )


def last_event_hash(*, session: Session, run_id: str) -> str | None:
    return session.scalar(
        select(RunEvent.chain_hash)
        .where(RunEvent.run_id == run_id)
        .order_by(RunEvent.seq.desc())
        .limit(1)
    )


def has_event_hash(*, session: Session, run_id: str, chain_hash: str) -> bool:
    return (
        session.scalar(
            select(RunEvent.id)
            .where(RunEvent.run_id == run_id, RunEvent.chain_hash == chain_hash)
            .limit(1)
        )
        is not None
    )


def has_event(*, session: Session, run_id: str, kind: str) -> bool:
    return (
        session.scalar(
            select(RunEvent.id).where(RunEvent.run_id == run_id, RunEvent.kind == kind).limit(1)
        )
        is not None
    )


def execution_reports(*, session: Session, run_id: str) -> list[ExecutionReport]:
    return list(
        session.scalars(
            select(ExecutionReport)
            .where(ExecutionReport.run_id == run_id)
            .order_by(ExecutionReport.task_index)
        )
    )


def queue_task_ids(run: Run) -> set[str]:
    """Every task id (as text, as decisions store it) in the run's queue."""
    return {str(t["id"]) for t in run.request["instance_data"]["tasks"]}


def request_key(*, session: Session, key: str) -> RequestKey | None:
    return session.scalar(select(RequestKey).where(RequestKey.key == key))
