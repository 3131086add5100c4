"""What a poll of a run needs of its whole record, aggregated by the database.

GET /runs/{id} shows totals over every decision (progress, workload, regret, LLM usage)
beside one page of them. Read row by row, each poll of a long run cost O(decisions) in
Python, and a run polled every 0.5 s paid that again and again as it grew; aggregated in
SQL, a poll reads a few numbers. The page itself is read as plain rows (no ORM objects).
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass, field
from typing import Any, cast

from sqlalchemy import Table, func, select
from sqlalchemy.orm import Session

from app.store.models import Attempt, Decision

_DECISIONS = cast(Table, Decision.__table__)
_ATTEMPTS = cast(Table, Attempt.__table__)


@dataclass(frozen=True)
class DecisionTotals:
    allocated: int  # decisions stored (a revision's pins included)
    by_robot: dict[int, int] = field(default_factory=dict)  # robot index -> decisions
    regret: float | None = 0.0  # summed; None if any decision has none


def decision_totals(*, session: Session, run_id: str) -> DecisionTotals:
    d = _DECISIONS.c
    by_robot = {
        int(robot): int(n)
        for robot, n in session.execute(
            select(d.robot, func.count()).where(d.run_id == run_id).group_by(d.robot)
        )
    }
    row = session.execute(
        select(func.count(), func.count(d.regret), func.sum(d.regret)).where(d.run_id == run_id)
    ).one()
    allocated, with_regret, regret = int(row[0]), int(row[1]), row[2]
    return DecisionTotals(
        allocated=allocated,
        by_robot=by_robot,
        regret=None if with_regret < allocated else float(regret or 0.0),
    )


def reply_totals(*, session: Session, run_id: str) -> list[Any]:
    """Per reply model (None: no model answered): (reply_model, replies, input_tokens,
    output_tokens, transport_retries, latency_ms), summed over the run's attempts."""
    a = _ATTEMPTS.c
    return list(
        session.execute(
            select(
                a.reply_model,
                func.count(),
                func.coalesce(func.sum(a.input_tokens), 0),
                func.coalesce(func.sum(a.output_tokens), 0),
                func.coalesce(func.sum(a.transport_retries), 0),
                func.coalesce(func.sum(a.latency_ms), 0.0),
            )
            .where(a.run_id == run_id)
            .group_by(a.reply_model)
        )
    )


def decision_page(*, session: Session, run_id: str, offset: int, limit: int | None) -> list[Any]:
    """Decisions in task order from the offset-th, at most limit of them (None: all), as
    plain rows with every column (attribute access as on the ORM rows)."""
    d = _DECISIONS.c
    query = select(_DECISIONS).where(d.run_id == run_id).order_by(d.task_index).offset(offset)
    return list(session.execute(query if limit is None else query.limit(limit)))


def page_indexes(*, session: Session, run_id: str, offset: int, limit: int | None) -> list[int]:
    """The task indexes of decision_page's rows (read from the index alone)."""
    d = _DECISIONS.c
    query = select(d.task_index).where(d.run_id == run_id).order_by(d.task_index).offset(offset)
    return [int(t) for t in session.scalars(query if limit is None else query.limit(limit))]


def decision_rows(*, session: Session, run_id: str, tasks: Sequence[int]) -> list[Any]:
    """The rows (as decision_page's) of these task indexes, in task order: one range read
    from the first to the last, kept to those asked for."""
    if not tasks:
        return []
    d = _DECISIONS.c
    wanted = set(tasks)
    query = (
        select(_DECISIONS)
        .where(d.run_id == run_id, d.task_index.between(min(wanted), max(wanted)))
        .order_by(d.task_index)
    )
    return [row for row in session.execute(query) if row.task_index in wanted]
