"""The app's own tables: runs, their events, decisions and reasoning attempts.

The LangGraph checkpointer keeps only the small graph state; everything that grows with
a run lives here, keyed so that a node re-executed after a crash upserts, never duplicates.
"""

from __future__ import annotations

from contextvars import ContextVar
from datetime import UTC, datetime
from typing import Any, ClassVar

from sqlalchemy import (
    JSON,
    Boolean,
    DateTime,
    Float,
    ForeignKey,
    Integer,
    String,
    Text,
    UniqueConstraint,
)
from sqlalchemy import event as orm_event
from sqlalchemy.orm import (
    DeclarativeBase,
    Mapped,
    ORMExecuteState,
    Session,
    declared_attr,
    mapped_column,
)

from app.domain.lifecycle import RunStatus
from app.domain.models import MAX_NAME_CHARS


def utcnow() -> datetime:
    return datetime.now(UTC)


def as_utc(value: datetime) -> datetime:
    """A stored time with its offset: every time is written in UTC, but SQLite hands it
    back naive (PostgreSQL keeps the offset)."""
    return value if value.tzinfo is not None else value.replace(tzinfo=UTC)


class Base(DeclarativeBase):
    type_annotation_map: ClassVar[dict[Any, Any]] = {dict[str, Any]: JSON, list[Any]: JSON}


# The store's shape of a run (why a run has five: app.runs.schemas.RunRequest).
class Run(Base):
    __tablename__ = "runs"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    status: Mapped[str] = mapped_column(String(16), index=True)
    request: Mapped[dict[str, Any]] = mapped_column(JSON)
    reasoner: Mapped[str] = mapped_column(String(32))
    mode: Mapped[str] = mapped_column(String(32))
    max_deviation: Mapped[float | None] = mapped_column(Float, nullable=True)
    n_tasks: Mapped[int] = mapped_column(Integer)
    n_robots: Mapped[int] = mapped_column(Integer)
    resumes: Mapped[int] = mapped_column(Integer, default=0)
    cancel_requested: Mapped[bool] = mapped_column(Boolean, default=False)
    error: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    updated_at: Mapped[datetime] = mapped_column(
        DateTime(timezone=True), default=utcnow, onupdate=utcnow
    )
    finished_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    # Scale-out on PostgreSQL: the process executing the run and until when (database clock).
    # An expired lease means that process stopped; any other process may then take the run.
    # Unused on SQLite, where one process owns the database.
    lease_owner: Mapped[str | None] = mapped_column(String(128), nullable=True)
    lease_expires_at: Mapped[datetime | None] = mapped_column(
        DateTime(timezone=True), nullable=True
    )
    # Idempotency-Key of the POST /runs that created the run, and a digest of its body, so
    # a retried request returns this run and a reused key with another body is refused.
    idempotency_key: Mapped[str | None] = mapped_column(
        String(255), nullable=True, unique=True, index=True
    )
    request_digest: Mapped[str | None] = mapped_column(String(64), nullable=True)
    # Revisions (docs/living-plans.md#revisions): the run this one revises, its place in the lineage
    # (0 = root), the revision that replaced this run, and the digest of the link to the parent (its
    # heads and the change set) that this run's chains start from (app.store.chain).
    revision_of: Mapped[str | None] = mapped_column(String(32), nullable=True, index=True)
    revision: Mapped[int] = mapped_column(Integer, default=0)
    superseded_by: Mapped[str | None] = mapped_column(String(32), nullable=True)
    chain_anchor: Mapped[str | None] = mapped_column(String(64), nullable=True)
    # The graph version (app.graph.version) the run started under; null for runs from
    # before it was recorded. A resume under another version is refused (status blocked).
    graph_version: Mapped[str | None] = mapped_column(String(64), nullable=True)
    # How its hash chains are built (app.store.chain.SCHEMES); null: v1, from before.
    chain_scheme: Mapped[str | None] = mapped_column(String(32), nullable=True)
    # The site it plans for (docs/estimates.md#sites): its robots are (site, name); its execution
    # reports feed that site's estimates (app.store.site_models).
    site: Mapped[str] = mapped_column(
        String(MAX_NAME_CHARS), default="default", server_default="default", index=True
    )


class RunSignature(Base):
    """A signature over a run's chain heads (at completion, at sign-off), outside the chains:
    it vouches for them and must not change them."""

    __tablename__ = "run_signatures"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    reason: Mapped[str] = mapped_column(String(32))
    key_id: Mapped[str] = mapped_column(String(32))
    payload: Mapped[dict[str, Any]] = mapped_column(JSON)
    signature: Mapped[str] = mapped_column(String(128))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class ArchivedRun(Base):
    """The tombstone of an archived run: what a lookup answers 410 Gone with."""

    __tablename__ = "archived_runs"

    id: Mapped[str] = mapped_column(String(32), primary_key=True)
    lineage_head: Mapped[str] = mapped_column(String(32))
    archive_file: Mapped[str] = mapped_column(String(255))
    heads: Mapped[dict[str, Any]] = mapped_column(JSON)
    verified: Mapped[bool] = mapped_column(Boolean)
    status: Mapped[str] = mapped_column(String(16))
    archived_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class _SeqChained:
    """The columns of a row in one run's `seq`-ordered hash chain (app.store.chain): the
    events while it runs, the annotations after. The unique (run_id, seq) is what keeps a
    re-executed node from appending the same link twice."""

    @declared_attr.directive
    @classmethod
    def __table_args__(cls) -> tuple[Any, ...]:
        return (UniqueConstraint("run_id", "seq", name=f"uq_{cls.__tablename__}_run_seq"),)  # type: ignore[attr-defined]

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    seq: Mapped[int] = mapped_column(Integer)
    kind: Mapped[str] = mapped_column(String(32))
    detail: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    # Tamper evidence: a hash over this row's content and the previous link of its run.
    chain_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)


class RunEvent(_SeqChained, Base):
    __tablename__ = "run_events"


class RunAnnotation(_SeqChained, Base):
    """A record made about a run after it finished (app.domain.annotations): append-only,
    hash-chained per run in `seq` order like the events."""

    __tablename__ = "run_annotations"

    # The Idempotency-Key of the POST that made it (keys are global, as for runs), and a
    # digest of that request, so a retry returns this row and a reused key is refused.
    # After the chain's columns (sort_order), where the migrations put them.
    idempotency_key: Mapped[str | None] = mapped_column(
        String(255), nullable=True, unique=True, index=True, sort_order=1
    )
    request_digest: Mapped[str | None] = mapped_column(String(64), nullable=True, sort_order=1)


# The store's shape of a decision (why a decision has four: app.graph.recorder.DecisionRecord).
class Decision(Base):
    __tablename__ = "decisions"
    __table_args__ = (UniqueConstraint("run_id", "task_index", name="uq_decisions_run_task"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    task_index: Mapped[int] = mapped_column(Integer)
    task_id: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    task_name: Mapped[str] = mapped_column(String(256))
    robot: Mapped[int] = mapped_column(Integer)
    robot_name: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    phase: Mapped[str] = mapped_column(String(16))
    expected_success: Mapped[float] = mapped_column(Float)
    reasoning: Mapped[str] = mapped_column(Text)
    confidence: Mapped[str] = mapped_column(String(16))
    tradeoff: Mapped[str] = mapped_column(Text)
    quality: Mapped[float] = mapped_column(Float)
    fallback: Mapped[bool] = mapped_column(Boolean)
    attempts: Mapped[int] = mapped_column(Integer)
    failure_log: Mapped[list[Any]] = mapped_column(JSON)
    loads_before: Mapped[list[Any]] = mapped_column(JSON)
    loads_after: Mapped[list[Any]] = mapped_column(JSON)
    balance_before: Mapped[float] = mapped_column(Float)
    balance_after: Mapped[float] = mapped_column(Float)
    severity_after: Mapped[str] = mapped_column(String(16))
    regret: Mapped[float | None] = mapped_column(Float, nullable=True)
    # A supervisor's review of this decision, when its run's policy asked for one: action,
    # reviewer (the key's name), reason, at, triggers, and overridden_from on an override.
    review: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    # Tamper evidence: a hash over this row's content and the previous link of its run.
    chain_hash: Mapped[str | None] = mapped_column(String(64), nullable=True)
    # A revision's pin (docs/living-plans.md#pins): copied from the parent's decision with this
    # chain hash. Null on every decision the graph made; hashed only when set, so older links hold.
    pinned: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    pinned_from: Mapped[str | None] = mapped_column(String(64), nullable=True)
    # docs/schedules.md#what-a-decision-records, a timed run (null otherwise): minutes from the
    # plan's start, the task's zone, minutes travelled just before it, its place in the decision
    # order (the chain order of a timed run) and how many minutes later it ends than an allowed
    # robot's earliest end.
    start: Mapped[float | None] = mapped_column(Float, nullable=True)
    end: Mapped[float | None] = mapped_column(Float, nullable=True)
    zone: Mapped[str | None] = mapped_column(String(200), nullable=True)
    travel: Mapped[float | None] = mapped_column(Float, nullable=True)
    seq: Mapped[int | None] = mapped_column(Integer, nullable=True)
    later_by: Mapped[float | None] = mapped_column(Float, nullable=True)
    # docs/allocation.md#teams, a team task: its members, one {"robot", "feature"} per unit in unit
    # order (`robot` is the first). Null for a single-robot task; hashed only when set.
    team: Mapped[list[Any] | None] = mapped_column(JSON(none_as_null=True), nullable=True)


class ExecutionReport(Base):
    """Where the site says a decided task stands (docs/living-plans.md#execution-reports): one row
    per run and task, moved forward only (started -> done | failed)."""

    __tablename__ = "execution_reports"
    __table_args__ = (UniqueConstraint("run_id", "task_index", name="uq_execution_run_task"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    task_index: Mapped[int] = mapped_column(Integer)
    task_id: Mapped[str] = mapped_column(String(MAX_NAME_CHARS))
    state: Mapped[str] = mapped_column(String(16))
    started_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    ended_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    updated_at: Mapped[datetime] = mapped_column(
        DateTime(timezone=True), default=utcnow, onupdate=utcnow
    )


class RequestKey(Base):
    """The Idempotency-Key of a POST that created no run of its own (execution reports),
    with a digest of its body: a retry answers as before, a reused key is refused."""

    __tablename__ = "request_keys"

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    key: Mapped[str] = mapped_column(String(255), unique=True, index=True)
    request_digest: Mapped[str] = mapped_column(String(64))
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


class Review(Base):
    """One decision a run paused for: its proposal and, once a supervisor answered, the
    resolution the worker resumes the graph with. One per run and task."""

    __tablename__ = "reviews"
    __table_args__ = (UniqueConstraint("run_id", "task_index", name="uq_reviews_run_task"),)

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    task_index: Mapped[int] = mapped_column(Integer)
    state: Mapped[str] = mapped_column(String(16), index=True)  # app.domain.review.ReviewState
    # The interrupt's payload: task, proposal, triggers and every robot as an alternative.
    proposal: Mapped[dict[str, Any]] = mapped_column(JSON)
    requested_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    resolution: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    resolved_at: Mapped[datetime | None] = mapped_column(DateTime(timezone=True), nullable=True)
    # The Idempotency-Key of the resolving POST and a digest of its body: a retry gets the
    # same answer instead of a 409, a reused key with another body is refused.
    idempotency_key: Mapped[str | None] = mapped_column(String(255), nullable=True)
    request_digest: Mapped[str | None] = mapped_column(String(64), nullable=True)


class Attempt(Base):
    __tablename__ = "attempts"
    __table_args__ = (
        UniqueConstraint("run_id", "task_index", "attempt", name="uq_attempts_run_task_attempt"),
    )

    id: Mapped[int] = mapped_column(Integer, primary_key=True, autoincrement=True)
    run_id: Mapped[str] = mapped_column(ForeignKey("runs.id", ondelete="CASCADE"), index=True)
    task_index: Mapped[int] = mapped_column(Integer)
    attempt: Mapped[int] = mapped_column(Integer)
    tier: Mapped[int] = mapped_column(Integer)
    system_prompt: Mapped[str] = mapped_column(Text)
    user_prompt: Mapped[str] = mapped_column(Text)
    reply_text: Mapped[str | None] = mapped_column(Text, nullable=True)
    reply_model: Mapped[str | None] = mapped_column(String(128), nullable=True)
    input_tokens: Mapped[int] = mapped_column(Integer, default=0)
    output_tokens: Mapped[int] = mapped_column(Integer, default=0)
    latency_ms: Mapped[float] = mapped_column(Float, default=0.0)
    transport_retries: Mapped[int] = mapped_column(Integer, default=0)
    reply_extra: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    parsed: Mapped[dict[str, Any] | None] = mapped_column(JSON, nullable=True)
    scores: Mapped[dict[str, Any]] = mapped_column(JSON, default=dict)
    quality: Mapped[float | None] = mapped_column(Float, nullable=True)
    accepted: Mapped[bool | None] = mapped_column(Boolean, nullable=True)
    hard_invalid: Mapped[str | None] = mapped_column(Text, nullable=True)
    feedback: Mapped[str | None] = mapped_column(Text, nullable=True)
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)


# -- one writer of runs.status -------------------------------------------------------------
# A run's status is moved only by app.runs.lifecycle, which checks the move against the
# transition table and writes the matching event. These guards make the rule hold at run
# time: an assignment to Run.status, or a bulk UPDATE of runs that sets status, while
# STATUS_WRITER is unset raises. Only app.runs.lifecycle.status_writes sets it: the context
# lives with its one user, the guards with the rows. (tests/runs/test_lifecycle.py also
# scans the source.)
STATUS_WRITER: ContextVar[bool] = ContextVar("ltaa_status_writer", default=False)


class StatusWriteError(RuntimeError):
    """Code outside app.runs.lifecycle tried to write a run's status."""


def _refuse(how: str) -> StatusWriteError:
    return StatusWriteError(
        f"runs.status was written {how} outside app.runs.lifecycle; move a run with "
        "app.runs.lifecycle.move() so the transition is checked and its event recorded"
    )


@orm_event.listens_for(Run.status, "set", propagate=True)
def _guard_status_set(target: Run, value: Any, old: Any, initiator: Any) -> None:
    if not STATUS_WRITER.get():
        raise _refuse(f"by assignment ({old!r} -> {value!r})")
    RunStatus(value)  # only statuses the lifecycle knows


@orm_event.listens_for(Session, "do_orm_execute")
def _guard_bulk_status(state: ORMExecuteState) -> None:
    if not state.is_update or STATUS_WRITER.get():
        return
    statement: Any = state.statement
    # The statement holds an annotated copy of the table, so compare by name.
    if getattr(getattr(statement, "table", None), "name", None) != Run.__tablename__:
        return
    # `_values` is the UPDATE's SET clause (no public accessor): keys are columns or names.
    values = getattr(statement, "_values", None) or {}
    if any(getattr(key, "key", key) == "status" for key in values):
        raise _refuse("by a bulk UPDATE")


class ConsoleSession(Base):
    """A supervisor's signed-in console session (app.console). The cookie holds a random
    token; only its digest is stored, with a fingerprint of the API key it was opened with
    (never the key), so removing that key from the configuration ends the session."""

    __tablename__ = "console_sessions"

    token_digest: Mapped[str] = mapped_column(String(64), primary_key=True)
    # None: opened while access control was off (no keys configured).
    key_fingerprint: Mapped[str | None] = mapped_column(String(64), nullable=True, index=True)
    csrf_token: Mapped[str] = mapped_column(String(64))
    created_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), default=utcnow)
    expires_at: Mapped[datetime] = mapped_column(DateTime(timezone=True), index=True)
