"""Supervisor reviews of decisions (docs/reviews.md#resolving-a-review): the queue of pending
reviews, and resolving one."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request, Response

from app.domain.lifecycle import RunStatus
from app.http.deps import SupervisorDep
from app.http.idempotency import IdempotencyKey, idempotency_of, mark_replayed
from app.http.responses import BODY, SUPERVISOR, errors
from app.reviews import service as reviews
from app.reviews.schemas import (
    AlternativeOut,
    PendingReviewOut,
    ProposalOut,
    ReviewRequest,
    ReviewResolvedOut,
    TeamUnitOut,
)
from app.runs.deps import RunIdPath, RunsDep

router = APIRouter(tags=["reviews"])

TaskIndexPath = Annotated[int, Path(ge=0, le=1_000_000, description="The task's queue index")]


@router.get("/reviews", response_model=list[PendingReviewOut], responses=errors(*SUPERVISOR))
def list_reviews(caller: SupervisorDep, runs: RunsDep) -> list[PendingReviewOut]:
    """For supervisors: decisions waiting for review, oldest first, each with its proposal,
    the triggers that fired and every robot as an alternative."""
    return [
        PendingReviewOut(
            run_id=r.run_id,
            task_index=r.task_index,
            task_id=r.task_id,
            task_name=r.task_name,
            proposal=ProposalOut(**r.proposal),
            triggers=r.triggers,
            alternatives=[AlternativeOut(**a) for a in r.alternatives],
            units=None if r.units is None else [TeamUnitOut(**u) for u in r.units],
            requested_at=r.requested_at,
        )
        for r in reviews.pending_reviews(sessions=runs.sessions)
    ]


@router.post(
    "/runs/{run_id}/reviews/{task_index}",
    response_model=ReviewResolvedOut,
    responses=errors(*SUPERVISOR, *BODY, 404, 409),
)
def resolve_review(
    caller: SupervisorDep,
    run_id: RunIdPath,
    task_index: TaskIndexPath,
    body: ReviewRequest,
    runs: RunsDep,
    request: Request,
    response: Response,
    idempotency_key: IdempotencyKey,
) -> ReviewResolvedOut:
    """For supervisors: approve the proposal or override it with another robot (a reason is
    required). The run is queued again and goes on with this decision."""
    resolved = reviews.resolve(
        sessions=runs.sessions,
        run_id=run_id,
        task_index=task_index,
        action=body.action,
        robot=body.robot,
        team=None if body.team is None else [(m.robot, m.feature) for m in body.team],
        reason=body.reason,
        reviewer=caller.name,
        idempotency=idempotency_of(idempotency_key, body),
    )
    mark_replayed(response, resolved.replayed)
    if not resolved.replayed:
        request.app.state.metrics.review_resolved(resolved.waited_s)
        runs.worker.submit(run_id)
    r = resolved.resolution
    return ReviewResolvedOut(
        run_id=run_id,
        task_index=task_index,
        action=r["action"],
        robot=r["robot"],
        team=r.get("team"),
        reason=r["reason"],
        reviewer=r["reviewer"],
        at=r["at"],
        triggers=r["triggers"],
        status=RunStatus.QUEUED,
    )
