"""Keyword-only data access for the app tables. Writes are upserts keyed by the natural
keys, so a node that LangGraph re-executes after a crash rewrites, never duplicates."""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import asdict
from functools import cache
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.dialects.postgresql import insert as postgresql_insert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session

from app.graph.recorder import AttemptRecord, DecisionRecord
from app.reasoners.base import ReasonerReply
from app.store.models import Attempt, Base, Decision, Run, RunEvent, utcnow

ACTIVE = ("queued", "running")


def get_run(*, session: Session, run_id: str, for_update: bool = False) -> Run | None:
    """`for_update` locks the row until the transaction ends (PostgreSQL; SQLite has no
    row locks and serialises writers anyway)."""
    return session.get(Run, run_id, with_for_update=for_update or None)


def list_runs(*, session: Session, status: str | None, limit: int, offset: int) -> list[Run]:
    query = select(Run).order_by(Run.created_at.desc(), Run.id)
    if status:
        query = query.where(Run.status == status)
    return list(session.scalars(query.limit(limit).offset(offset)))


def runs_with_status(*, session: Session, statuses: Sequence[str]) -> list[Run]:
    return list(session.scalars(select(Run).where(Run.status.in_(statuses)).order_by(Run.id)))


def set_status(*, session: Session, run: Run, status: str, error: str | None = None) -> None:
    run.status = status
    run.error = error
    if status in ("completed", "failed", "cancelled"):
        run.finished_at = utcnow()


def add_event(*, session: Session, run_id: str, kind: str, detail: dict[str, Any]) -> RunEvent:
    seq = session.scalar(select(func.coalesce(func.max(RunEvent.seq), 0))
                         .where(RunEvent.run_id == run_id)) or 0
    event = RunEvent(run_id=run_id, seq=seq + 1, kind=kind, detail=detail)
    session.add(event)
    return event


def events(*, session: Session, run_id: str) -> list[RunEvent]:
    return list(session.scalars(select(RunEvent).where(RunEvent.run_id == run_id)
                                .order_by(RunEvent.seq)))


def decisions(*, session: Session, run_id: str) -> list[Decision]:
    return list(session.scalars(select(Decision).where(Decision.run_id == run_id)
                                .order_by(Decision.task_index)))


def attempts(*, session: Session, run_id: str) -> list[Attempt]:
    return list(session.scalars(select(Attempt).where(Attempt.run_id == run_id)
                                .order_by(Attempt.task_index, Attempt.attempt)))


def attempt_replies(*, session: Session, run_id: str) -> list[Any]:
    """Only the reply columns of a run's attempts (no prompts): what a replay needs."""
    return list(session.execute(
        select(Attempt.task_index, Attempt.attempt, Attempt.reply_text, Attempt.reply_model,
               Attempt.input_tokens, Attempt.output_tokens, Attempt.reply_extra)
        .where(Attempt.run_id == run_id)))


@cache
def _upsert_statement(dialect: str, model: type[Base], keys: tuple[str, ...]) -> Any:
    # Built once and executed with parameters, so SQLAlchemy's compiled cache is hit.
    insert = {"sqlite": sqlite_insert, "postgresql": postgresql_insert}[dialect]
    stmt = insert(model.__table__)
    updates = {c.name: stmt.excluded[c.name] for c in model.__table__.columns
               if c.name not in keys and not c.primary_key}
    return stmt.on_conflict_do_update(index_elements=list(keys), set_=updates)


def _upsert(session: Session, model: type[Base], values: dict[str, Any],
            keys: tuple[str, ...]) -> None:
    """INSERT ... ON CONFLICT (keys) DO UPDATE, in one statement (SQLite and PostgreSQL)."""
    stmt = _upsert_statement(session.get_bind().dialect.name, model, keys)
    session.execute(stmt, values)


def upsert_decision(*, session: Session, run_id: str, record: DecisionRecord) -> None:
    values = asdict(record)
    values["task_id"] = str(record.task_id)
    _upsert(session, Decision, {"run_id": run_id, **values, "created_at": utcnow()},
            ("run_id", "task_index"))


def _attempt_values(record: AttemptRecord) -> dict[str, Any]:
    reply = record.reply
    return {
        "tier": record.tier,
        "system_prompt": record.system_prompt,
        "user_prompt": record.user_prompt,
        "reply_text": reply.text if reply else None,
        "reply_model": reply.model if reply else None,
        "input_tokens": reply.input_tokens if reply else 0,
        "output_tokens": reply.output_tokens if reply else 0,
        "latency_ms": reply.latency_ms if reply else 0.0,
        "transport_retries": reply.transport_retries if reply else 0,
        "reply_extra": dict(reply.extra) if reply else {},
        "parsed": record.parsed,
        "scores": record.scores,
        "quality": record.quality,
        "accepted": record.accepted,
        "hard_invalid": record.hard_invalid,
        "feedback": record.feedback,
    }


def upsert_attempt(*, session: Session, run_id: str, record: AttemptRecord) -> None:
    values = {"run_id": run_id, "task_index": record.task_index, "attempt": record.attempt,
              **_attempt_values(record), "created_at": utcnow()}
    _upsert(session, Attempt, values, ("run_id", "task_index", "attempt"))


def attempt_record(row: Attempt) -> AttemptRecord:
    reply = None
    if row.reply_text is not None:
        reply = ReasonerReply(
            text=row.reply_text, input_tokens=row.input_tokens, output_tokens=row.output_tokens,
            latency_ms=row.latency_ms, model=row.reply_model,
            transport_retries=row.transport_retries, extra=dict(row.reply_extra or {}),
        )
    return AttemptRecord(
        task_index=row.task_index, attempt=row.attempt, tier=row.tier,
        system_prompt=row.system_prompt, user_prompt=row.user_prompt, reply=reply,
        parsed=row.parsed, scores=dict(row.scores or {}), quality=row.quality,
        accepted=row.accepted, hard_invalid=row.hard_invalid, feedback=row.feedback,
    )


def last_attempted_task(*, session: Session, run_id: str) -> int:
    """The highest task index with a stored attempt, or -1."""
    last = session.scalar(select(func.max(Attempt.task_index)).where(Attempt.run_id == run_id))
    return -1 if last is None else int(last)


def get_attempt(*, session: Session, run_id: str, task_index: int, attempt: int) -> Attempt | None:
    return session.scalar(select(Attempt).where(Attempt.run_id == run_id,
                                                Attempt.task_index == task_index,
                                                Attempt.attempt == attempt))


def decision_record(row: Decision) -> DecisionRecord:
    fields = DecisionRecord.__dataclass_fields__
    return DecisionRecord(**{name: getattr(row, name) for name in fields})
