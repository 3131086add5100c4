"""Execution reports (docs/living-plans.md#execution-reports): where the site says each decided task
stands.

States move forward only: started -> done | failed, done and failed are final, and the
same report again is a no-op; a `started` after the task ended is stale, refused like any
step back (docs/living-plans.md#execution-reports); a task is not done (or failed) at a time
before it started.
A report on a run that was revised is refused (the site reports to the head of the
lineage). While the run is unfinished each accepted report is an event of its record;
after it finished it goes to the annotation chain, so a completed run's decision and event
chains (and every sign-off over them) stay as they were.
"""

from __future__ import annotations

from collections.abc import Collection, Mapping, Sequence
from dataclasses import dataclass
from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.domain.annotations import AnnotationKind
from app.domain.errors import DomainError, IdempotencyKeyReusedError, RunNotFoundError
from app.domain.lifecycle import FINISHED
from app.runs import lifecycle
from app.runs.lifecycle import EventKind
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store import site_repository as site_repo
from app.store.db import transaction
from app.store.idempotency import Idempotency
from app.store.models import ExecutionReport, RequestKey, Run, as_utc, utcnow


class ExecutionState(StrEnum):
    STARTED = "started"
    DONE = "done"
    FAILED = "failed"


FINAL = frozenset({ExecutionState.DONE, ExecutionState.FAILED})


@dataclass(frozen=True)
class Update:
    task_id: str
    state: ExecutionState
    at: datetime | None = None


class ExecutionConflictError(DomainError):
    """A report that conflicts with what is stored (409). `location` is the part of the
    request `field` points into: the body (an update's task or state), or the path (the run
    itself, when it was revised)."""

    status_code = 409

    def __init__(
        self, field: str, message: str, code: str = "conflict", *, location: str = "body"
    ) -> None:
        super().__init__(field, message, code=code)
        self.location = location


def allowed(current: ExecutionState | None, to: ExecutionState) -> bool:
    """Forward only; the same state again is allowed (a no-op)."""
    if current is None or current == to:
        return True
    return current == ExecutionState.STARTED and to in FINAL


def head_of(session: Session, run: Run) -> str:
    """The newest revision in the run's lineage (the run itself if it was never revised)."""
    seen = {run.id}
    current = run
    while current.superseded_by is not None:
        following = repo.get_run(session=session, run_id=current.superseded_by)
        if following is None or following.id in seen:
            break
        seen.add(following.id)
        current = following
    return current.id


def report(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
    updates: Sequence[Update],
    idempotency: Idempotency | None = None,
) -> dict[str, str]:
    """Apply the updates as one transaction (all or none); returns every reported task's
    state now, by task id."""
    try:
        return _report(sessions, run_id, updates, idempotency)
    except IntegrityError:
        if idempotency is None:
            raise
        # The same key at the same moment: the other request won; answer as it did.
        return _report(sessions, run_id, updates, idempotency)


def _report(
    sessions: sessionmaker[Session],
    run_id: str,
    updates: Sequence[Update],
    idempotency: Idempotency | None,
) -> dict[str, str]:
    with transaction(sessions) as session:
        # Locked: a revision made at this moment must see these reports, or refuse them.
        run = repo.get_run(session=session, run_id=run_id, for_update=True)
        if run is None:
            raise RunNotFoundError(run_id)
        if idempotency is not None:
            earlier = repo.request_key(session=session, key=idempotency.key)
            if earlier is not None:
                if earlier.request_digest != idempotency.digest or earlier.run_id != run_id:
                    raise IdempotencyKeyReusedError.for_run(earlier.run_id)
                return current_states(session, run_id, [u.task_id for u in updates])
        if run.superseded_by is not None:
            head = head_of(session, run)
            raise ExecutionConflictError(
                "run_id",
                f"run '{run_id}' was revised; report execution to the head of its "
                f"revisions, run '{head}' (POST /runs/{head}/execution)",
                code="revised",
                location="path",
            )
        changed, outcomes = _apply_updates(session, run, updates)
        if changed:
            _record_reports(session, run, changed, outcomes)
        if idempotency is not None:
            session.add(
                RequestKey(key=idempotency.key, request_digest=idempotency.digest, run_id=run_id)
            )
        session.flush()
        return current_states(session, run_id, [u.task_id for u in updates])


def _apply_updates(
    session: Session, run: Run, updates: Sequence[Update]
) -> tuple[list[dict[str, Any]], list[site_repo.Reported]]:
    """Check each update in order and write it to the run's report rows; (the changes the
    record will say, the final outcomes the site learns from). A repeat changes nothing."""
    run_id = run.id
    tasks = repo.queue_task_ids(run)
    decided = {d.task_id: d.task_index for d in decision_repo.decided_task_ids(session, run_id)}
    stored = {r.task_id: r for r in repo.execution_reports(session=session, run_id=run_id)}
    changed: list[dict[str, Any]] = []
    outcomes: list[site_repo.Reported] = []
    pending: dict[str, ExecutionState] = {}
    started_here: dict[str, bool] = {}  # task id -> its `started` here carried `at`
    for i, update in enumerate(updates):
        _check_task(i, update, run_id, tasks, decided)
        row = stored.get(update.task_id)
        current = pending.get(update.task_id) or (
            ExecutionState(row.state) if row is not None else None
        )
        if not allowed(current, update.state):
            stale = (
                "; a `started` sent after the task ended is stale: send each task's states "
                "in order (the same state again is a no-op)"
                if update.state == ExecutionState.STARTED
                else ""
            )
            raise ExecutionConflictError(
                f"updates.{i}.state",
                f"task '{update.task_id}' is {current}; execution states move forward "
                f"only (started -> done | failed), not {current} -> {update.state}{stale}",
                code="backwards",
            )
        if current == update.state:
            continue
        pending[update.task_id] = update.state
        at = _report_time(i, update, row)
        changed.append(
            {
                "task_id": update.task_id,
                "task_index": decided[update.task_id],
                "state": update.state.value,
                "at": at.isoformat(),
                **_server_clock(update),
            }
        )
        if row is None:
            row = ExecutionReport(
                run_id=run_id,
                task_index=decided[update.task_id],
                task_id=update.task_id,
                state=update.state.value,
            )
            session.add(row)
            stored[update.task_id] = row
        row.state = update.state.value
        if update.state == ExecutionState.STARTED:
            row.started_at = at
            started_here[update.task_id] = update.at is not None
        else:
            row.ended_at = at
            outcomes.append(
                site_repo.Reported(
                    row.task_index,
                    update.task_id,
                    update.state.value,
                    at,
                    row.started_at,
                    together_without_at=site_repo.together_without_at(
                        started_here, update.task_id, at_sent=update.at is not None
                    ),
                )
            )
    return changed, outcomes


def _check_task(
    i: int, update: Update, run_id: str, tasks: Collection[str], decided: Mapping[str, int]
) -> None:
    field = f"updates.{i}.task_id"
    if update.task_id not in tasks:
        raise DomainError(
            field, f"task '{update.task_id}' is not in run '{run_id}'", code="unknown_task"
        )
    if update.task_id not in decided:
        raise ExecutionConflictError(
            field,
            f"task '{update.task_id}' has not been decided yet in run '{run_id}'; "
            "report only decided tasks",
            code="undecided",
        )


def _report_time(i: int, update: Update, row: ExecutionReport | None) -> datetime:
    """When the update happened (now if it says not), never before the task started."""
    # Stored in UTC: SQLite keeps no offset, so 09:30+05:00 would read back as 09:30Z.
    at = as_utc(update.at).astimezone(UTC) if update.at is not None else utcnow()
    started = row.started_at if row is not None else None
    if update.state in FINAL and started is not None and at < as_utc(started):
        sent = at.isoformat() if update.at is not None else f"now ({at.isoformat()})"
        raise DomainError(
            f"updates.{i}.at",
            f"task '{update.task_id}' started at {as_utc(started).isoformat()}; it "
            f"cannot be {update.state} earlier, at {sent}",
            code="before_started",
        )
    return at


def _record_reports(
    session: Session,
    run: Run,
    changed: list[dict[str, Any]],
    outcomes: list[site_repo.Reported],
) -> None:
    """An event of an unfinished run's record, an annotation of a finished one."""
    detail = {"updates": changed}
    if run.status in FINISHED:
        record: Any = lifecycle.record_annotation(
            session, run_id=run.id, kind=AnnotationKind.EXECUTION_REPORTED, detail=detail
        )
    else:
        record = lifecycle.record_event(
            session, run_id=run.id, kind=EventKind.EXECUTION_REPORTED, detail=detail
        )
    if outcomes:
        # The site's outcome rows (docs/estimates.md#counting-each-report-once), received
        # when the record says: the rebuild from the record reads the same time.
        session.flush()
        site_repo.record_outcomes(
            session=session, run=run, reported=outcomes, received_at=record.created_at
        )


def _server_clock(update: Update) -> dict[str, str]:
    """What the record adds to an update sent without `at`: its time is the server's, so
    the rebuild of the site's rows (app.sites.rebuild) can tell, as the report did."""
    return {} if update.at is not None else dict(site_repo.SERVER_CLOCK)


def current_states(session: Session, run_id: str, task_ids: Sequence[str]) -> dict[str, str]:
    rows = {r.task_id: r.state for r in repo.execution_reports(session=session, run_id=run_id)}
    return {t: rows[t] for t in task_ids if t in rows}


def states_of(*, sessions: sessionmaker[Session], run_id: str) -> dict[int, ExecutionReport]:
    """Every reported task of a run, by task index."""
    with sessions() as session:
        return {r.task_index: r for r in repo.execution_reports(session=session, run_id=run_id)}
