"""A run's progress as a sequence read back from the app tables: one item per finalised
decision and one per run event, in the order they were written.

Reading the tables (rather than listening inside the worker) lets a watcher connect late,
reconnect, or watch a run executing in another process, and it can never disturb the run:
watching is read-only.
"""

from __future__ import annotations

import re
from collections.abc import Iterable, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any, Literal, TypeVar

from sqlalchemy import select
from sqlalchemy.orm import Session, sessionmaker

from app.domain.lifecycle import FINISHED, EventKind
from app.domain.models import TaskId
from app.store.models import Decision, Run, RunEvent, as_utc

_OPENING = (EventKind.CREATED, EventKind.STARTED, EventKind.RESUMED)
# ASCII digits only (\d would take any script's), as the OpenAPI pattern says.
CURSOR_PATTERN = r"^[ \t]*([0-9]{1,9})-([0-9]{1,9})[ \t]*$"
_CURSOR = re.compile(CURSOR_PATTERN)
# Sent as their own SSE event type, so a supervisor's console can listen for them alone.
_REVIEW = (EventKind.REVIEW_REQUESTED, EventKind.REVIEW_RESOLVED, EventKind.REVIEW_CLOSED)
R = TypeVar("R", RunEvent, Decision)


@dataclass(frozen=True)
class Cursor:
    """How far a watcher has read: run events up to `events` (their seq) and the first
    `decisions` decisions (decisions are stored contiguously from task 0)."""

    events: int = 0
    decisions: int = 0

    def __str__(self) -> str:
        return f"{self.events}-{self.decisions}"

    @classmethod
    def parse(cls, text: str) -> Cursor:
        match = _CURSOR.match(text)
        if match is None:
            raise ValueError("expected an event id sent by this stream, like '3-17'")
        return cls(int(match[1]), int(match[2]))


@dataclass(frozen=True)
class ProgressItem:
    kind: Literal["decision", "run", "review"]
    data: dict[str, Any]
    at: datetime
    cursor: Cursor  # the position after this item: its SSE id


@dataclass(frozen=True)
class ProgressBatch:
    items: list[ProgressItem]
    cursor: Cursor
    status: str  # the run's status, read before these rows
    ended: bool  # the run had ended before these rows were read: nothing more will come


def _decision_data(d: Decision, ids: Sequence[TaskId]) -> dict[str, Any]:
    return {
        "task_index": d.task_index,
        "task_id": ids[d.task_index] if d.task_index < len(ids) else d.task_id,
        "task_name": d.task_name,
        "robot": d.robot_name,
        "phase": d.phase,
        "expected_success": d.expected_success,
        "quality": d.quality,
        "fallback": d.fallback,
        "attempts": d.attempts,
        "regret": d.regret,
        "balance_after": d.balance_after,
        "review": d.review,
    }


def _event_data(e: RunEvent) -> dict[str, Any]:
    return {"seq": e.seq, "kind": e.kind, "detail": e.detail, "at": as_utc(e.created_at)}


def _monotonic(rows: Iterable[R]) -> list[tuple[datetime, R]]:
    """Pair rows with a non-decreasing time. A decision rewritten after a resume carries
    the rewrite's time, which must not move it ahead of a later task's decision."""
    out: list[tuple[datetime, R]] = []
    for row in rows:
        at = row.created_at if not out else max(out[-1][0], row.created_at)
        out.append((at, row))
    return out


def run_status(*, sessions: sessionmaker[Session], run_id: str) -> str | None:
    with sessions() as session:
        return session.scalar(select(Run.status).where(Run.id == run_id))


def task_ids(*, sessions: sessionmaker[Session], run_id: str) -> list[TaskId]:
    """The run's task ids as its request gave them (the decisions table keeps them as text:
    a watcher should see 300 where GET /runs/{id} says 300, not "300")."""
    with sessions() as session:
        request = session.scalar(select(Run.request).where(Run.id == run_id))
    # The stored request as it is (no RunSpec): a request an older release stored reads too.
    tasks = ((request or {}).get("instance_data") or {}).get("tasks") or []
    return [t["id"] for t in tasks]


def read_progress(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
    cursor: Cursor,
    ids: Sequence[TaskId],
) -> ProgressBatch | None:
    """Everything after `cursor`, or None if there is no such run. `ids`: task_ids(...)."""
    with sessions() as session:
        # Status first: rows read afterwards include everything written before it changed,
        # so a run seen ended here is complete in the rows below.
        status = session.scalar(select(Run.status).where(Run.id == run_id))
        if status is None:
            return None
        events = session.scalars(
            select(RunEvent)
            .where(RunEvent.run_id == run_id, RunEvent.seq > cursor.events)
            .order_by(RunEvent.seq)
        )
        decisions = session.scalars(
            select(Decision)
            .where(Decision.run_id == run_id, Decision.task_index >= cursor.decisions)
            .order_by(Decision.task_index)
        )
        rows: list[tuple[datetime, int, RunEvent | Decision]] = [
            (at, 0 if e.kind in _OPENING else 2, e) for at, e in _monotonic(events)
        ]
        contiguous: list[Decision] = []
        for d in decisions:
            if d.task_index != cursor.decisions + len(contiguous):
                break  # never skip a gap: the missing decision is still being written
            contiguous.append(d)
        rows += [(at, 1, d) for at, d in _monotonic(contiguous)]
        # Merged by write time; each kind keeps its own order whatever the clock says.
        rows.sort(key=lambda row: (row[0], row[1]))

        items: list[ProgressItem] = []
        for at, _, row in rows:
            if isinstance(row, RunEvent):
                cursor = Cursor(row.seq, cursor.decisions)
                kind: Literal["run", "review"] = "review" if row.kind in _REVIEW else "run"
                items.append(ProgressItem(kind, _event_data(row), at, cursor))
            else:
                cursor = Cursor(cursor.events, row.task_index + 1)
                items.append(ProgressItem("decision", _decision_data(row, ids), at, cursor))
    return ProgressBatch(items=items, cursor=cursor, status=status, ended=status in FINISHED)
