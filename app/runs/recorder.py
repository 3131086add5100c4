"""The durable Recorder: the graph's side effects written to the app tables."""

from __future__ import annotations

import logging
import threading
from collections.abc import Callable

from sqlalchemy.orm import Session, sessionmaker

from app.domain.usage import Usage
from app.graph.recorder import AttemptRecord, DecisionRecord, RunCancelled
from app.observability.logs import bind
from app.runs import records
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import transaction

# Called inside each write's transaction; raises LeaseLost when this process no longer
# holds the run (PostgreSQL scale-out), so the write is rolled back.
Fence = Callable[[Session], None]
log = logging.getLogger("ltaa.runs")


class LeaseLost(RunCancelled):
    """Another process took this run (our lease expired): stop without writing anything."""


class RunSuperseded(RunCancelled):
    """A revision replaced this run (SPEC 10): stop without writing anything more."""


class RunStop:
    """Why a run should stop at the next node boundary: a cancel, the process draining,
    (scale-out) the run's lease passing to another process, or a revision replacing it."""

    def __init__(self) -> None:
        self.cancelled = threading.Event()
        self.shutting_down = threading.Event()
        self.lease_lost = threading.Event()
        self.superseded = threading.Event()

    def requested(self) -> bool:
        return (
            self.cancelled.is_set()
            or self.shutting_down.is_set()
            or self.lease_lost.is_set()
            or self.superseded.is_set()
        )


def status_fence(run_id: str, stop: RunStop) -> Fence:
    """Every write of a run is fenced by its state: one conditional UPDATE of its row
    `WHERE status = 'running'` in the write's own transaction. A revision supersedes the
    parent in one transaction that writes that row first, so a write racing it either
    commits before (and is pinned) or finds the run superseded and rolls back."""

    def fence(session: Session) -> None:
        if not repo.still_running(session=session, run_id=run_id):
            stop.superseded.set()
            raise RunSuperseded(run_id)

    return fence


def fences(*parts: Fence | None) -> Fence | None:
    """One fence that runs each given part in order."""
    given = [f for f in parts if f is not None]
    if not given:
        return None

    def fence(session: Session) -> None:
        for part in given:
            part(session)

    return fence


class SqlRecorder:
    def __init__(
        self,
        *,
        run_id: str,
        sessions: sessionmaker[Session],
        stop: RunStop,
        fence: Fence | None = None,
    ) -> None:
        self.run_id = run_id
        self._sessions = sessions
        self._stop = stop
        self._fence = fence
        # Write-through cache: this process wrote these rows, so reads need no query.
        # After a restart the cache starts empty and reads fall through to the table.
        self._attempts: dict[tuple[int, int], AttemptRecord] = {}
        # Tasks after the last one with a stored attempt (read once, at the first miss)
        # have only the attempts this recorder wrote: one writer per run (the lease fence
        # stops this one if another process takes the run), so a miss there needs no query.
        self._stored_through: int | None = None

    def check_cancelled(self) -> None:
        if self._stop.lease_lost.is_set():
            raise LeaseLost(self.run_id)
        if self._stop.superseded.is_set():
            raise RunSuperseded(self.run_id)
        if self._stop.requested():
            raise RunCancelled(self.run_id)

    def before_reason(self, task_index: int, attempt: int) -> None:
        # Reasoner (and SDK) logs during this node's call name the run and task.
        bind(run_id=self.run_id, task_index=task_index)

    def save_attempt(self, record: AttemptRecord) -> None:
        with transaction(self._sessions) as session:
            if self._fence is not None:
                self._fence(session)
            decision_repo.upsert_attempt(
                session=session, run_id=self.run_id, values=records.attempt_values(record)
            )
        self._attempts[(record.task_index, record.attempt)] = record.copy()
        # Only the current task's attempts are ever read back.
        for key in [k for k in self._attempts if k[0] < record.task_index]:
            del self._attempts[key]

    def attempt(self, task_index: int, attempt: int) -> AttemptRecord | None:
        cached = self._attempts.get((task_index, attempt))
        if cached is not None:
            return cached.copy()
        if self._stored_through is None:
            with self._sessions() as session:
                self._stored_through = decision_repo.last_attempted_task(
                    session=session, run_id=self.run_id
                )
        if task_index > self._stored_through:
            return None
        with self._sessions() as session:
            row = decision_repo.get_attempt(
                session=session, run_id=self.run_id, task_index=task_index, attempt=attempt
            )
            return records.attempt_record(row) if row is not None else None

    def save_decision(self, record: DecisionRecord) -> None:
        with transaction(self._sessions) as session:
            if self._fence is not None:
                self._fence(session)
            decision_repo.upsert_decision(
                session=session, run_id=self.run_id, values=records.decision_values(record)
            )
        log.log(
            logging.WARNING if record.fallback else logging.INFO,
            "task %d -> %s (Q %.2f, %d attempt(s)%s)",
            record.task_index,
            record.robot_name,
            record.quality,
            record.attempts,
            ", rules fallback" if record.fallback else "",
            extra={"run_id": self.run_id, "task_index": record.task_index},
        )

    def decisions(self) -> list[DecisionRecord]:
        with self._sessions() as session:
            return [
                records.decision_record(row)
                for row in decision_repo.decisions(session=session, run_id=self.run_id)
            ]

    def usage(self) -> Usage:
        with self._sessions() as session:
            return records.usage_of(decision_repo.reply_costs(session=session, run_id=self.run_id))
