"""Keyword-only data access for a run's decisions and attempts. Writes are upserts keyed by the
natural keys, so a node that LangGraph re-executes after a crash rewrites, never duplicates;
each decision is chained (app.store.chain) as it is written."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from functools import cache
from typing import Any, cast

from sqlalchemy import (
    BindParameter,
    Connection,
    Integer,
    String,
    Table,
    and_,
    bindparam,
    func,
    select,
)
from sqlalchemy.dialects.postgresql import Insert as PostgresqlInsert
from sqlalchemy.dialects.postgresql import insert as postgresql_insert
from sqlalchemy.dialects.sqlite import Insert as SqliteInsert
from sqlalchemy.dialects.sqlite import insert as sqlite_insert
from sqlalchemy.orm import Session, defer

from app.store import chain
from app.store.fenced import WriteGuard, Written, fenced_upsert
from app.store.models import (
    Attempt,
    Base,
    Decision,
    utcnow,
)
from app.store.repository import chain_anchor, chain_genesis


@cache
def _upsert_statement(dialect: str, model: type[Base], keys: tuple[str, ...]) -> Any:
    # Built once and executed with parameters, so SQLAlchemy's compiled cache is hit.
    table = cast(Table, model.__table__)
    stmt: SqliteInsert | PostgresqlInsert = (
        sqlite_insert(table) if dialect == "sqlite" else postgresql_insert(table)
    )
    updates = {
        c.name: stmt.excluded[c.name]
        for c in table.columns
        if c.name not in keys and not c.primary_key
    }
    return stmt.on_conflict_do_update(index_elements=list(keys), set_=updates)


def _upsert(
    session: Session, model: type[Base], values: dict[str, Any], keys: tuple[str, ...]
) -> None:
    """INSERT ... ON CONFLICT (keys) DO UPDATE, in one statement (SQLite and PostgreSQL)."""
    stmt = _upsert_statement(session.get_bind().dialect.name, model, keys)
    session.execute(stmt, values)


def decisions_page(
    *,
    session: Session,
    run_id: str,
    after_task: int,
    limit: int,
    pinned: bool | None = None,
    by_seq: bool = False,
) -> list[Decision]:
    """`pinned`: True only a revision's pins, False only the rest, None every decision.
    `by_seq`: in a timed run's decision order (`after_task` is then a seq), pins excluded."""
    if by_seq:
        return list(
            session.scalars(
                select(Decision)
                .where(Decision.run_id == run_id, Decision.seq > after_task)
                .order_by(Decision.seq)
                .limit(limit)
            )
        )
    query = select(Decision).where(Decision.run_id == run_id, Decision.task_index > after_task)
    if pinned is True:
        query = query.where(Decision.pinned.is_(True))
    elif pinned is False:
        query = query.where(Decision.pinned.is_(None))
    return list(session.scalars(query.order_by(Decision.task_index).limit(limit)))


def attempts_of_tasks(
    *, session: Session, run_id: str, first: int, last: int
) -> dict[int, list[Attempt]]:
    """Attempts of task indexes first..last, by task, in attempt order."""
    by_task: dict[int, list[Attempt]] = {}
    for row in session.scalars(
        select(Attempt)
        .where(Attempt.run_id == run_id, Attempt.task_index.between(first, last))
        .order_by(Attempt.task_index, Attempt.attempt)
    ):
        by_task.setdefault(row.task_index, []).append(row)
    return by_task


def decisions(*, session: Session, run_id: str) -> list[Decision]:
    return list(
        session.scalars(
            select(Decision).where(Decision.run_id == run_id).order_by(Decision.task_index)
        )
    )


def decisions_slice(
    *, session: Session, run_id: str, offset: int, limit: int | None
) -> list[Decision]:
    """Decisions in task order from the offset-th, at most limit of them (None: all)."""
    query = (
        select(Decision)
        .where(Decision.run_id == run_id)
        .order_by(Decision.task_index)
        .offset(offset)
    )
    return list(session.scalars(query if limit is None else query.limit(limit)))


def decision_outcomes(*, session: Session, run_id: str) -> list[Any]:
    """(task_index, robot, regret, expected_success, team) of every decision in task order:
    the few columns a run's totals need, without loading each row's record."""
    return list(
        session.execute(
            select(Decision.task_index, Decision.robot, Decision.regret)
            .add_columns(Decision.expected_success, Decision.team)
            .where(Decision.run_id == run_id)
            .order_by(Decision.task_index)
        )
    )


def attempts(*, session: Session, run_id: str) -> list[Attempt]:
    return list(
        session.scalars(
            select(Attempt)
            .where(Attempt.run_id == run_id)
            .order_by(Attempt.task_index, Attempt.attempt)
        )
    )


def attempt_replies(*, session: Session, run_id: str) -> list[Any]:
    """Only the reply columns of a run's attempts (no prompts): what a replay needs."""
    return list(
        session.execute(
            select(
                Attempt.task_index,
                Attempt.attempt,
                Attempt.reply_text,
                Attempt.reply_model,
                Attempt.input_tokens,
                Attempt.output_tokens,
                Attempt.reply_extra,
            ).where(Attempt.run_id == run_id)
        )
    )


def reply_costs(*, session: Session, run_id: str) -> list[Any]:
    """Only the cost columns of a run's attempts (no prompts, no replies): what usage
    counts, without reading megabytes of text per poll of a long run."""
    return list(
        session.execute(
            select(
                Attempt.reply_model,
                Attempt.input_tokens,
                Attempt.output_tokens,
                Attempt.transport_retries,
                Attempt.latency_ms,
            ).where(Attempt.run_id == run_id)
        )
    )


@cache
def _decision_link_statement() -> Any:
    # Built once (building it took half the helper's time) and executed with parameters.
    d, a = Decision.__table__.c, Attempt.__table__.c
    run_id: BindParameter[str] = bindparam("run_id", type_=String())
    task_index: BindParameter[int] = bindparam("task_index", type_=Integer())
    prev = (
        select(func.coalesce(d.chain_hash, chain.UNCHAINED))
        .where(d.run_id == run_id, d.task_index < task_index)
        .order_by(d.task_index.desc())
        .limit(1)
        .scalar_subquery()
    )
    anchor = select(prev.label("prev")).subquery()
    return (
        select(anchor.c.prev, *(a[name] for name in chain.ATTEMPT_FIELDS))
        .select_from(
            anchor.outerjoin(
                Attempt.__table__, and_(a.run_id == run_id, a.task_index == task_index)
            )
        )
        .order_by(a.attempt)
    )


def _decision_chain_hash(session: Session, run_id: str, values: dict[str, Any]) -> str:
    """The decision's link over its content, its task's attempts and the previous decision's
    hash, with one indexed SELECT: the previous link joined to the task's attempts.

    The attempts must already be written (in this transaction or an earlier one); content
    equal to what is stored (a re-upsert after a crash) gives the stored hash again.
    A revision's chain runs through its pins first, then the graph's decisions (both in
    task order): see revision_chain_order."""
    rows = session.execute(
        _decision_link_statement(), {"run_id": run_id, "task_index": values["task_index"]}
    ).all()
    attempts = [row._mapping for row in rows if row.attempt is not None]
    anchor = chain_anchor(session=session, run_id=run_id)
    if anchor is not None:
        prev = _revision_prev(session, run_id, values)
    elif values.get("seq") is not None:
        prev = _sequenced_prev(session, run_id, values["seq"])
    else:
        prev = rows[0].prev
    prev_link = (
        prev
        if prev is not None
        else chain_genesis(session=session, table="decisions", run_id=run_id)
    )
    return chain.decision_link(prev_link, values, chain.attempts_digest(attempts))


def _sequenced_prev(session: Session, run_id: str, seq: int) -> str | None:
    """The link before a timed run's decision (docs/schedules.md#the-chain-in-decision-order): the
    run's decisions are chained in the order the graph made them (`seq`), which is not task
    order."""
    row = session.execute(
        select(Decision.chain_hash)
        .where(Decision.run_id == run_id, Decision.seq < seq, Decision.pinned.is_(None))
        .order_by(Decision.seq.desc())
        .limit(1)
    ).first()
    return None if row is None else chain.next_prev(row.chain_hash)


def _revision_prev(session: Session, run_id: str, values: Mapping[str, Any]) -> str | None:
    """The link before this decision in a revision's chain order (None: it is the first)."""
    t, pinned, seq = values["task_index"], bool(values.get("pinned")), values.get("seq")

    def last(*where: Any, key: Any = Decision.task_index) -> str | None:
        row = session.execute(
            select(Decision.chain_hash)
            .where(Decision.run_id == run_id, *where)
            .order_by(key.desc())
            .limit(1)
        ).first()
        return None if row is None else chain.next_prev(row.chain_hash)

    if pinned:
        return last(Decision.pinned.is_(True), Decision.task_index < t)
    if seq is not None:  # a timed revision: its own decisions in the order it made them
        made = last(Decision.pinned.is_(None), Decision.seq < seq, key=Decision.seq)
        return made or last(Decision.pinned.is_(True))
    return last(Decision.pinned.is_(None), Decision.task_index < t) or last(
        Decision.pinned.is_(True)
    )


def revision_chain_order(pinned: Sequence[int], decided: Sequence[int]) -> list[int]:
    """The task indexes of a revision's decisions in chain order: pins, then the rest."""
    pins = set(pinned)
    return sorted(pins) + sorted(t for t in decided if t not in pins)


def sequenced_order(*, session: Session, run_id: str) -> list[int] | None:
    """A timed run's graph decisions (task indexes) in the order they were made and chained
    (docs/schedules.md#the-chain-in-decision-order); None for a run whose decisions carry no order
    (chained in task order)."""
    rows = session.execute(
        select(Decision.task_index, Decision.seq)
        .where(Decision.run_id == run_id, Decision.pinned.is_(None))
        .order_by(Decision.seq)
    ).all()
    if not rows or rows[0].seq is None:
        return None
    return [row.task_index for row in rows]


def upsert_decision(*, session: Session, run_id: str, values: Mapping[str, Any]) -> None:
    """`values`: the decision's columns but run_id, chain_hash and created_at."""
    row = dict(values)
    row["chain_hash"] = _decision_chain_hash(session, run_id, row)
    _upsert(
        session,
        Decision,
        {"run_id": run_id, **row, "created_at": utcnow()},
        ("run_id", "task_index"),
    )


def decision_chain_hash(*, session: Session, run_id: str, values: Mapping[str, Any]) -> str:
    """The link a decision with these `values` gets when written now (read from the table:
    the previous link and its task's stored attempts)."""
    return _decision_chain_hash(session, run_id, dict(values))


DECISION_KEYS = ("run_id", "task_index")
ATTEMPT_KEYS = ("run_id", "task_index", "attempt")


def _write(
    connection: Connection,
    model: type[Base],
    row: dict[str, Any],
    keys: tuple[str, ...],
    guard: WriteGuard | None,
) -> Written:
    if guard is not None:
        return fenced_upsert(connection, model, row, keys, guard)
    connection.execute(_upsert_statement(connection.dialect.name, model, keys), row)
    return Written(ok=True)


def write_decision(
    *,
    connection: Connection,
    run_id: str,
    values: Mapping[str, Any],
    chain_hash: str,
    guard: WriteGuard | None,
) -> Written:
    """Upsert a decision with its (already computed) chain link, in one statement that is
    fenced by `guard` (nothing is written if the run no longer holds)."""
    row = {"run_id": run_id, **values, "chain_hash": chain_hash, "created_at": utcnow()}
    return _write(connection, Decision, row, DECISION_KEYS, guard)


def write_attempt(
    *, connection: Connection, run_id: str, values: Mapping[str, Any], guard: WriteGuard | None
) -> Written:
    """Upsert an attempt (as upsert_attempt) in one statement fenced by `guard`."""
    row = {"run_id": run_id, **values, "created_at": utcnow()}
    return _write(connection, Attempt, row, ATTEMPT_KEYS, guard)


def upsert_attempt(*, session: Session, run_id: str, values: Mapping[str, Any]) -> None:
    """`values`: the attempt's columns (task_index and attempt included) but run_id and
    created_at."""
    _upsert(
        session,
        Attempt,
        {"run_id": run_id, **values, "created_at": utcnow()},
        ("run_id", "task_index", "attempt"),
    )


def last_attempted_task(*, session: Session, run_id: str) -> int:
    """The highest task index with a stored attempt, or -1."""
    last = session.scalar(select(func.max(Attempt.task_index)).where(Attempt.run_id == run_id))
    return -1 if last is None else int(last)


def get_attempt(*, session: Session, run_id: str, task_index: int, attempt: int) -> Attempt | None:
    return session.scalar(
        select(Attempt).where(
            Attempt.run_id == run_id, Attempt.task_index == task_index, Attempt.attempt == attempt
        )
    )


def tokens_spent(*, session: Session, run_id: str) -> int:
    """Input + output tokens of a run's replies that name a model (as app.domain.usage
    counts them): what its LLM calls have cost so far, from the record."""
    total = session.scalar(
        select(func.sum(Attempt.input_tokens + Attempt.output_tokens)).where(
            Attempt.run_id == run_id, Attempt.reply_model.is_not(None)
        )
    )
    return int(total or 0)


def decided_indexes(*, session: Session, run_id: str, pinned: bool | None = None) -> list[int]:
    query = select(Decision.task_index).where(Decision.run_id == run_id)
    if pinned is True:
        query = query.where(Decision.pinned.is_(True))
    elif pinned is False:
        query = query.where(Decision.pinned.is_(None))
    return list(session.scalars(query.order_by(Decision.task_index)))


def decided_task_ids(session: Session, run_id: str) -> list[Any]:
    """(task_id, task_index) of every stored decision of a run."""
    return list(
        session.execute(
            select(Decision.task_id, Decision.task_index).where(Decision.run_id == run_id)
        )
    )


def decision_count(*, session: Session, run_id: str) -> int:
    return int(
        session.scalar(select(func.count()).select_from(Decision).where(Decision.run_id == run_id))
        or 0
    )


def decision_outline(*, session: Session, run_id: str) -> list[Any]:
    """(task_index, robot, balance_after, team) of every decision, in task order: the columns
    a chart of the whole run needs, without the text of 10,000 reasonings."""
    return list(
        session.execute(
            select(Decision.task_index, Decision.robot, Decision.balance_after, Decision.team)
            .where(Decision.run_id == run_id)
            .order_by(Decision.task_index)
        )
    )


def decisions_window(*, session: Session, run_id: str, offset: int, limit: int) -> list[Decision]:
    return list(
        session.scalars(
            select(Decision)
            .where(Decision.run_id == run_id, Decision.task_index >= offset)
            .order_by(Decision.task_index)
            .limit(limit)
        )
    )


def attempt_summaries_of_tasks(
    *, session: Session, run_id: str, first: int, last: int
) -> dict[int, list[Attempt]]:
    """As attempts_of_tasks, with the prompts and the reply left unloaded (read on demand)."""
    by_task: dict[int, list[Attempt]] = {}
    for row in session.scalars(
        select(Attempt)
        .options(
            defer(Attempt.system_prompt), defer(Attempt.user_prompt), defer(Attempt.reply_text)
        )
        .where(Attempt.run_id == run_id, Attempt.task_index.between(first, last))
        .order_by(Attempt.task_index, Attempt.attempt)
    ):
        by_task.setdefault(row.task_index, []).append(row)
    return by_task
