"""Revisions (docs/living-plans.md#revisions): a new run that replaces its parent when the site
changes.

Creating a revision and stopping its parent is one transaction. It begins by writing the
parent's row (a lock: SQLite's write lock, a PostgreSQL row lock), so the decisions it pins
are exactly those the parent had committed; every recorder write of the parent checks, in
the statement that writes it, that the parent is still `running` (app.runs.recorder.Fence,
app.store.fenced), so a decision it was computing when it was superseded is rolled back,
never stored.
"""

from __future__ import annotations

import uuid
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import update
from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.audit.heads import chain_heads
from app.config import Settings
from app.domain.annotations import AnnotationKind
from app.domain.errors import DomainError, RunNotFoundError
from app.domain.estimates import DurationSource, RateSource
from app.domain.lifecycle import FINISHED
from app.plans.reports import head_of
from app.plans.revision_pins import ParentDecision
from app.plans.revision_plan import RevisionPlan, plan_revision
from app.plans.revision_rates import revision_spec
from app.plans.revision_times import ReportedTimes
from app.reasoners.factory import check_reasoner
from app.runs import lifecycle, records, review_gate
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.service import insert_run
from app.runs.spec import RunSpec
from app.runs.worker import RunWorker
from app.store import chain
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import transaction
from app.store.idempotency import Idempotency, run_for_key
from app.store.models import ExecutionReport, Run, as_utc, utcnow

REVISABLE = frozenset(
    {
        RunStatus.QUEUED,
        RunStatus.RUNNING,
        RunStatus.INTERRUPTED,
        RunStatus.AWAITING_REVIEW,
        RunStatus.COMPLETED,
    }
)


class RevisionConflictError(DomainError):
    status_code = 409
    location = "path"

    def __init__(self, message: str, code: str = "conflict") -> None:
        super().__init__("run_id", message, code=code)


@dataclass(frozen=True)
class RevisionRequest:
    changes: Sequence[Mapping[str, Any]]
    pin: str | Mapping[str, Any]
    reason: str
    reasoner: str | None = None
    model: str | None = None
    # docs/estimates.md#using-the-estimates: None inherits the parent's.
    rates: RateSource | None = None
    durations: DurationSource | None = None
    # docs/living-plans.md#a-revision-in-time: the time the revision plans from (aware); None: the
    # request's arrival.
    now: datetime | None = None


def _lock(session: Session, run_id: str) -> Run:
    """Write the parent's row first: from here on this transaction holds the write lock
    (SQLite) or the row lock (PostgreSQL), and the parent's fenced writes wait for it."""
    touched = session.execute(
        update(Run)
        .where(Run.id == run_id)
        .values(updated_at=Run.updated_at)
        .returning(Run.id)
        .execution_options(synchronize_session=False)
    ).first()
    if touched is None:
        raise RunNotFoundError(run_id)
    run = repo.get_run(session=session, run_id=run_id, for_update=True)
    if run is None:
        raise RunNotFoundError(run_id)
    return run


def lineage_tokens(session: Session, run: Run) -> int:
    """Tokens spent by the run and every run it revised."""
    total, seen = 0, set()
    current: Run | None = run
    while current is not None and current.id not in seen:
        seen.add(current.id)
        total += decision_repo.tokens_spent(session=session, run_id=current.id)
        current = (
            repo.get_run(session=session, run_id=current.revision_of)
            if current.revision_of
            else None
        )
    return total


def create_revision(
    *,
    sessions: sessionmaker[Session],
    worker: RunWorker,
    parent_id: str,
    request: RevisionRequest,
    settings: Settings,
    idempotency: Idempotency | None = None,
) -> tuple[Run, bool]:
    """(the revision, whether an earlier request with the same Idempotency-Key made it)."""
    _check_reasoner(settings, request)
    if idempotency is not None:
        earlier = run_for_key(sessions=sessions, idempotency=idempotency)
        if earlier is not None:
            return earlier, True
    try:
        run, parent_was_active = _create(
            sessions, parent_id, request, idempotency, settings.prior_strength
        )
    except IntegrityError:
        if idempotency is None:
            raise
        earlier = run_for_key(sessions=sessions, idempotency=idempotency)
        if earlier is None:
            raise
        return earlier, True
    if parent_was_active:
        worker.supersede(parent_id)
    worker.submit(run.id)
    return run, False


def _create(
    sessions: sessionmaker[Session],
    parent_id: str,
    request: RevisionRequest,
    idempotency: Idempotency | None,
    prior_strength: float,
) -> tuple[Run, bool]:
    with transaction(sessions) as session:
        parent, status = _revisable_parent(session, parent_id)
        reports = {
            r.task_index: r for r in repo.execution_reports(session=session, run_id=parent_id)
        }
        plan = _plan(session, parent, request, reports)
        spec, learned = revision_spec(
            session=session,
            spec=plan.spec,
            changes=request.changes,
            rates=request.rates,
            durations=request.durations,
            strength=prior_strength,
        )
        run = _new_revision(
            session, parent, status, request, plan, spec, learned, reports, idempotency
        )
        active = _stop_parent(session, parent, status, run.id, request.reason)
        session.flush()
    return run, active


def _revisable_parent(session: Session, parent_id: str) -> tuple[Run, RunStatus]:
    """The parent, locked, if it may be revised now."""
    parent = _lock(session, parent_id)
    if parent.superseded_by is not None:
        head = head_of(session, parent)
        raise RevisionConflictError(
            f"run '{parent_id}' was already revised; revise the head of its revisions, "
            f"run '{head}' (POST /runs/{head}/revisions)",
            code="already_revised",
        )
    status = RunStatus(parent.status)
    if status not in REVISABLE:
        raise RevisionConflictError(
            f"run '{parent_id}' is {status.value}; only a queued, running, interrupted, "
            "awaiting review or completed run can be revised (start a new run instead)"
        )
    return parent, status


def _plan(
    session: Session,
    parent: Run,
    request: RevisionRequest,
    reports: Mapping[int, ExecutionReport],
) -> RevisionPlan:
    """The revision planned from what the parent committed and the site reported."""
    parent_spec = RunSpec.from_json(parent.request)
    rows = decision_repo.decisions(session=session, run_id=parent.id)
    decided = {r.task_index: ParentDecision(records.decision_record(r), r.chain_hash) for r in rows}
    times = {
        t: ReportedTimes(
            r.state,
            None if r.started_at is None else as_utc(r.started_at),
            None if r.ended_at is None else as_utc(r.ended_at),
        )
        for t, r in reports.items()
    }
    budget = parent_spec.token_budget
    if budget is not None:
        budget = max(0, budget - lineage_tokens(session, parent))
    return plan_revision(
        parent_spec=parent_spec,
        decided=decided,
        execution={t: r.state for t, r in reports.items()},
        changes=request.changes,
        pin=request.pin,
        reasoner=request.reasoner,
        model=request.model,
        parent_id=parent.id,
        token_budget=budget,
        reports=times,
        now=request.now,
        # Whole seconds, as a run's default start: minutes read cleanly.
        arrival=utcnow().replace(microsecond=0),
    )


def _new_revision(
    session: Session,
    parent: Run,
    status: RunStatus,
    request: RevisionRequest,
    plan: RevisionPlan,
    spec: RunSpec,
    learned: list[dict[str, Any]],
    reports: Mapping[int, ExecutionReport],
    idempotency: Idempotency | None,
) -> Run:
    """The revision's row, its chain anchor linked to the parent's heads, and its pins."""
    parent_id = parent.id
    heads = chain_heads(session, parent_id).as_dict()
    run_id = uuid.uuid4().hex
    revision_no = parent.revision + 1
    link = {
        "parent": parent_id,
        "parent_heads": heads,
        "changes": [dict(c) for c in request.changes],
        "pin": request.pin if isinstance(request.pin, str) else dict(request.pin),
        "reason": request.reason,
    }
    detail = {
        **link,
        "revision": revision_no,
        "parent_status": status.value,
        "pinned": plan.pinned_task_ids,
        # The site's reports on pinned tasks, carried to the revision (_carry_execution).
        "execution": _carried(plan.pinned_rows, reports),
        "added_tasks": plan.added_tasks,
        "removed_tasks": plan.removed_tasks,
        "fleet_changes": plan.fleet_changes + learned,
        **_time_detail(plan),
    }
    run = insert_run(
        session,
        run_id=run_id,
        spec=spec,
        problem=plan.problem,
        idempotency=idempotency,
        created=detail,
        first_event=EventKind.REVISED,
        revision_of=parent_id,
        revision=revision_no,
        chain_anchor=chain.revision_anchor(chain.revision_link(link)),
    )
    for values in plan.pinned_rows:
        decision_repo.upsert_decision(session=session, run_id=run_id, values=values)
    _carry_execution(session, run_id, plan.pinned_rows, reports)
    return run


def _stop_parent(
    session: Session, parent: Run, status: RunStatus, run_id: str, reason: str
) -> bool:
    """Mark the parent superseded by the revision; whether it was still active."""
    parent.superseded_by = run_id
    active = status not in FINISHED
    if active:
        if status == RunStatus.AWAITING_REVIEW:
            # Its pending decision was never stored, so it is not pinned; a later
            # resolution of that review is a 409.
            review_gate.close_pending(session, parent.id, "the run was revised")
        # The other process holding it (PostgreSQL) stops at its next heartbeat.
        parent.cancel_requested = True
        lifecycle.move(
            session,
            parent,
            RunStatus.SUPERSEDED,
            event=EventKind.SUPERSEDED,
            detail={"by": run_id, "reason": reason},
        )
    else:
        lifecycle.record_annotation(
            session,
            run_id=parent.id,
            kind=AnnotationKind.SUPERSEDED_BY,
            detail={"by": run_id, "reason": reason},
        )
    return active


def _time_detail(plan: RevisionPlan) -> dict[str, Any]:
    """docs/living-plans.md#a-revision-in-time: when a timed revision plans from, and the reported
    times it pinned."""
    if plan.now is None:
        return {}
    tasks = plan.problem.instance.tasks
    return {
        "now": plan.now.isoformat(),
        "not_before": plan.problem.not_before,
        "pinned_times": {
            str(tasks[t].id): {"start": start, "end": end}
            for t, (start, end) in sorted(plan.facts.items())
        },
    }


def _carried_rows(
    pinned_rows: Sequence[Mapping[str, Any]], reports: Mapping[int, ExecutionReport]
) -> list[tuple[Mapping[str, Any], ExecutionReport]]:
    by_task_id = {r.task_id: r for r in reports.values()}
    out = []
    for values in pinned_rows:
        was = by_task_id.get(str(values["task_id"]))
        if was is not None:
            out.append((values, was))
    return out


def _carried(
    pinned_rows: Sequence[Mapping[str, Any]], reports: Mapping[int, ExecutionReport]
) -> dict[str, str]:
    return {was.task_id: was.state for _, was in _carried_rows(pinned_rows, reports)}


def _carry_execution(
    session: Session,
    run_id: str,
    pinned_rows: Sequence[Mapping[str, Any]],
    reports: Mapping[int, ExecutionReport],
) -> None:
    """A pinned task keeps where the site said it stands: the revision, the head the site
    now reports to, must know a task is done, or its own revision (pin "reported") would
    plan it again. Unpinned tasks are planned afresh, so their old state stays behind."""
    for values, was in _carried_rows(pinned_rows, reports):
        session.add(
            ExecutionReport(
                run_id=run_id,
                task_index=values["task_index"],
                task_id=was.task_id,
                state=was.state,
                started_at=was.started_at,
                ended_at=was.ended_at,
            )
        )


def _check_reasoner(settings: Settings, request: RevisionRequest) -> None:
    """An overriding reasoner must be one this server can build (known, key configured)."""
    if request.reasoner is None:
        return
    try:
        check_reasoner(request.reasoner, settings=settings, model=request.model)
    except DomainError as exc:
        raise DomainError("reasoner", exc.message, code=exc.code) from None


@dataclass(frozen=True)
class LineageEntry:
    """One run of a lineage, with what its revision event says (None for the root)."""

    run: Run
    reason: str | None
    changes: list[dict[str, Any]]
    pinned: int


def lineage_entries(*, sessions: sessionmaker[Session], run_id: str) -> list[LineageEntry]:
    """The lineage, root to head, each revision with its reason, changes and pin count:
    read from its first event (`revised`), the record the revision's chain starts with."""
    runs = lineage(sessions=sessions, run_id=run_id)
    out = []
    with sessions() as session:
        for run in runs:
            detail: dict[str, Any] = {}
            if run.revision_of is not None:
                first = repo.events_page(session=session, run_id=run.id, after_seq=0, limit=1)
                if first and first[0].kind == EventKind.REVISED:
                    detail = dict(first[0].detail or {})
            out.append(
                LineageEntry(
                    run=run,
                    reason=detail.get("reason"),
                    changes=list(detail.get("changes", [])),
                    pinned=len(detail.get("pinned", [])),
                )
            )
    return out


def lineage(*, sessions: sessionmaker[Session], run_id: str) -> list[Run]:
    """The run's revisions, root to head."""
    with sessions() as session:
        run = repo.get_run(session=session, run_id=run_id)
        if run is None:
            raise RunNotFoundError(run_id)
        root, seen = run, {run.id}
        while root.revision_of is not None:
            parent = repo.get_run(session=session, run_id=root.revision_of)
            if parent is None or parent.id in seen:
                break
            seen.add(parent.id)
            root = parent
        out, listed = [root], {root.id}
        while out[-1].superseded_by is not None:
            following = repo.get_run(session=session, run_id=out[-1].superseded_by)
            if following is None or following.id in listed:
                break
            listed.add(following.id)
            out.append(following)
        return out
