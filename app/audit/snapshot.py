"""The moment trace/verify judges a run at: which rows of each chain it checks.

Verify reads its pages in short sessions (app.audit.record_pages), so a live run (a timed run
still deciding, or a paused one whose in-flight decision lands) keeps appending while it
reads. A timed run is chained in decision order (`seq`), whose task indexes are not
consecutive, so verify needs that order up front; rows read after it that the order does
not hold were taken for missing ones ("task_index 15 to 26 is missing"). The snapshot
holds the order and, for each chain, the last key it covers, all read from one statement
per chain, and the pages stop there: verify checks exactly the prefix that existed then.
Rows are only ever appended in key order (task order, `seq` for a timed run's decisions),
so the prefix up to a key read later is the prefix that existed at the snapshot.
"""

from __future__ import annotations

from dataclasses import dataclass

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.audit.record_pages import chain_passes
from app.store import decision_repository as decision_repo
from app.store.models import Decision, RunAnnotation, RunEvent


@dataclass(frozen=True)
class DecisionPass:
    """One pass over a run's decisions in chain order (app.audit.record_pages.chain_passes), with
    the last key the snapshot holds: a seq when `by_seq`, else a task index (-1: none)."""

    pinned: bool | None
    by_seq: bool
    last: int


@dataclass(frozen=True)
class Snapshot:
    order: list[int] | None  # the decisions' task indexes in chain order, if not task order
    passes: tuple[DecisionPass, ...]
    last_event: int  # the last event seq (0: none)
    last_annotation: int  # the last annotation seq (0: none)


def snapshot(session: Session, run_id: str, revision_of: str | None) -> Snapshot:
    """Read after the run's status, so a run seen completed has all its rows here."""
    rows = session.execute(
        select(Decision.task_index, Decision.seq, Decision.pinned)
        .where(Decision.run_id == run_id)
        .order_by(Decision.task_index)
    ).all()
    pins = [r.task_index for r in rows if r.pinned]
    # As decision_repository.sequenced_order, NULLs first (SQLite's order) on both back-ends.
    made = sorted((r for r in rows if not r.pinned), key=lambda r: (r.seq is not None, r.seq or 0))
    sequenced = bool(made) and made[0].seq is not None
    order: list[int] | None = None
    if sequenced:  # a timed run: chained in the order the graph decided, after any pins
        order = pins + [r.task_index for r in made]
    elif revision_of is not None:  # pins first, then the graph's decisions
        order = decision_repo.revision_chain_order(pins, [r.task_index for r in made])

    def last(pinned: bool | None, by_seq: bool) -> int:
        keys = [
            r.seq if by_seq else r.task_index
            for r in rows
            if pinned is None or bool(r.pinned) == pinned
        ]
        return max((k for k in keys if k is not None), default=-1)

    passes = tuple(
        DecisionPass(pinned, by_seq, last(pinned, by_seq))
        for pinned, by_seq in chain_passes(revision_of, sequenced)
    )
    last_event = session.scalar(select(func.max(RunEvent.seq)).where(RunEvent.run_id == run_id))
    last_annotation = session.scalar(
        select(func.max(RunAnnotation.seq)).where(RunAnnotation.run_id == run_id)
    )
    return Snapshot(
        order=order,
        passes=passes,
        last_event=int(last_event or 0),
        last_annotation=int(last_annotation or 0),
    )
