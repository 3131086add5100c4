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


@dataclass
class Tally:
    """A run's totals over its settled prefix: the decisions of task indexes 0..through
    (every one stored) and their tasks' attempts. Neither changes once stored (a resumed
    node rewrites the same values), so a poll folds in only what was stored since."""

    through: int = -1
    allocated: int = 0
    by_robot: dict[int, int] = field(default_factory=dict)
    with_regret: int = 0
    regret: float = 0.0
    # reply model -> [replies, input tokens, output tokens, transport retries, latency ms]
    replies: dict[str | None, list[float]] = field(default_factory=dict)

    def totals(self) -> DecisionTotals:
        return DecisionTotals(
            allocated=self.allocated,
            by_robot=dict(self.by_robot),
            regret=None if self.with_regret < self.allocated else self.regret,
        )

    def reply_rows(self) -> list[tuple[Any, ...]]:
        """As reply_totals' rows."""
        return [(model, *sums) for model, sums in self.replies.items()]


def _copy(tally: Tally, through: int) -> Tally:
    return Tally(
        through=through,
        allocated=tally.allocated,
        by_robot=dict(tally.by_robot),
        with_regret=tally.with_regret,
        regret=tally.regret,
        replies={model: list(sums) for model, sums in tally.replies.items()},
    )


def tally(*, session: Session, run_id: str, settled: Tally) -> tuple[Tally, Tally]:
    """(the run's totals now, the settled prefix to keep for the next call), reading only
    the decisions and attempts of task indexes after `settled.through`.

    Decisions are stored as a prefix of the queue (pins and the free tasks in order), so
    the stored task indexes from 0 with no gap are settled; a revision's pins past the
    gap, and the attempts of the task being decided, are counted but read again next time."""
    d, a = _DECISIONS.c, _ATTEMPTS.c
    rows = session.execute(
        select(d.task_index, d.robot, d.regret)
        .where(d.run_id == run_id, d.task_index > settled.through)
        .order_by(d.task_index)
    ).all()
    through = settled.through
    for row in rows:
        if row.task_index != through + 1:
            break
        through += 1
    keep, now = _copy(settled, through), _copy(settled, through)
    for row in rows:
        for part in (keep, now) if row.task_index <= through else (now,):
            part.by_robot[int(row.robot)] = part.by_robot.get(int(row.robot), 0) + 1
            part.allocated += 1
            if row.regret is not None:
                part.with_regret += 1
                part.regret += float(row.regret)
    for attempt in session.execute(
        select(
            a.task_index,
            a.reply_model,
            a.input_tokens,
            a.output_tokens,
            a.transport_retries,
            a.latency_ms,
        ).where(a.run_id == run_id, a.task_index > settled.through)
    ):
        values = (1, attempt[2] or 0, attempt[3] or 0, attempt[4] or 0, attempt[5] or 0.0)
        for part in (keep, now) if attempt.task_index <= through else (now,):
            sums = part.replies.setdefault(attempt.reply_model, [0, 0, 0, 0, 0.0])
            for i, value in enumerate(values):
                sums[i] += value
    return now, keep


def unplaced_pins(*, session: Session, run_id: str) -> set[int]:
    """Task indexes of a revision's pins stored without times (not reported when it was made:
    docs/living-plans.md#a-revision-in-time)."""
    return set(
        session.scalars(
            select(Decision.task_index).where(
                Decision.run_id == run_id, Decision.pinned.is_(True), Decision.start.is_(None)
            )
        )
    )
