"""Living plans (docs/living-plans.md): execution reports, revisions, the lineage and the diff."""

from __future__ import annotations

from fastapi import APIRouter, Response, status

from app.domain.lifecycle import RunStatus
from app.http.deps import ClientDep, SettingsDep
from app.http.idempotency import CREATED_HEADERS, IdempotencyKey, keyed, mark_replayed
from app.http.responses import BODY, CLIENT, errors
from app.plans import diff, revisions
from app.plans import reports as execution
from app.plans.schemas import (
    DiffOut,
    ExecutionOut,
    ExecutionRequest,
    RevisionCreated,
    RevisionItem,
    RevisionRequestIn,
    RobotChange,
    ScheduleDiff,
    SideMetrics,
)
from app.runs.deps import RunIdPath, RunsDep
from app.store.idempotency import Idempotency

router = APIRouter(prefix="/runs", tags=["living plans"])


def _idempotency(key: str | None, run_id: str, body: dict[str, object]) -> Idempotency | None:
    # The run in the path is part of the request: the same body to another run differs.
    return keyed(key, {"run_id": run_id, "body": body})


@router.post(
    "/{run_id}/execution",
    response_model=ExecutionOut,
    responses=errors(*CLIENT, *BODY, 404, 409),
)
def report_execution(
    caller: ClientDep,
    run_id: RunIdPath,
    body: ExecutionRequest,
    runs: RunsDep,
    idempotency_key: IdempotencyKey,
) -> ExecutionOut:
    """Report where decided tasks stand on site: started -> done | failed, forward only;
    repeating a report is a no-op. A revised run refuses reports (409 naming the head)."""
    states = execution.report(
        sessions=runs.sessions,
        run_id=run_id,
        updates=[
            execution.Update(
                task_id=str(u.task_id), state=execution.ExecutionState(u.state), at=u.at
            )
            for u in body.updates
        ],
        idempotency=_idempotency(
            idempotency_key, run_id, body.model_dump(mode="json", exclude_unset=True)
        ),
    )
    return ExecutionOut(run_id=run_id, states=states)


@router.post(
    "/{run_id}/revisions",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=RevisionCreated,
    responses={202: {"headers": CREATED_HEADERS}, **errors(*CLIENT, *BODY, 404, 409)},
)
def create_revision(
    caller: ClientDep,
    run_id: RunIdPath,
    body: RevisionRequestIn,
    runs: RunsDep,
    settings: SettingsDep,
    response: Response,
    idempotency_key: IdempotencyKey,
) -> RevisionCreated:
    """Revise a run when the site changes: a new run (same worker, graph and durability)
    that keeps the pinned decisions and re-plans the rest. An unfinished parent becomes
    `superseded`; a completed one stays completed. Both name the revision."""
    sent = body.model_dump(mode="json", exclude_unset=True)
    run, replayed = revisions.create_revision(
        sessions=runs.sessions,
        worker=runs.worker,
        parent_id=run_id,
        settings=settings,
        request=revisions.RevisionRequest(
            # As sent: a set_mode without max_deviation (the mode's default) differs from
            # one with `"max_deviation": null` (no cap).
            changes=[
                {**c.model_dump(mode="json", exclude_unset=True), "type": c.type}
                for c in body.changes
            ],
            pin=body.model_dump(mode="json")["pin"],
            reason=body.reason,
            reasoner=body.reasoner,
            model=body.model,
            rates=body.rates,
            durations=body.durations,
            now=body.now,
        ),
        idempotency=_idempotency(idempotency_key, run_id, sent),
    )
    response.headers["Location"] = f"/runs/{run.id}"
    mark_replayed(response, replayed)
    return RevisionCreated(
        id=run.id,
        revision_of=run_id if run.revision_of is None else run.revision_of,
        revision=run.revision,
        status=RunStatus.QUEUED if replayed else RunStatus(run.status),
        location=f"/runs/{run.id}",
    )


@router.get(
    "/{run_id}/revisions", response_model=list[RevisionItem], responses=errors(*CLIENT, 404)
)
def list_revisions(caller: ClientDep, run_id: RunIdPath, runs: RunsDep) -> list[RevisionItem]:
    """The run's lineage, root to head."""
    return [
        RevisionItem(
            id=e.run.id,
            revision=e.run.revision,
            revision_of=e.run.revision_of,
            superseded_by=e.run.superseded_by,
            status=RunStatus(e.run.status),
            created_at=e.run.created_at,
            reason=e.reason,
        )
        for e in revisions.lineage_entries(sessions=runs.sessions, run_id=run_id)
    ]


@router.get("/{run_id}/diff", response_model=DiffOut, responses=errors(*CLIENT, 404, 409))
def get_diff(caller: ClientDep, run_id: RunIdPath, runs: RunsDep) -> DiffOut:
    """A revision against its parent: tasks whose robot changed, added and removed tasks,
    fleet changes, expected success and balance before and after; on a timed revision
    (docs/living-plans.md#the-diff-in-time) the tasks that moved in time and the makespan before and
    after."""
    d = diff.diff(sessions=runs.sessions, run_id=run_id)
    return DiffOut(
        run_id=d.run_id,
        parent=d.parent,
        robot_changes=[RobotChange(**c) for c in d.robot_changes],
        added_tasks=d.added_tasks,
        removed_tasks=d.removed_tasks,
        fleet_changes=d.fleet_changes,
        before=SideMetrics(**d.before),
        after=SideMetrics(**d.after),
        schedule=None if d.schedule is None else ScheduleDiff.model_validate(d.schedule),
    )
