"""The run's side of supervisor reviews (docs/reviews.md#which-decisions-wait-for-review): the
review policy a run is created with, and what the worker does when the graph pauses for a person.

A run whose review policy fires pauses inside the graph (`interrupt()`, app.graph.review);
the worker then records the review here and moves the run to `awaiting_review`, holding
no slot. A supervisor's resolution (app.reviews.service) queues it again; whichever worker
claims it resumes the graph with the resolution this module finds. A cancel or a revision
closes the pending review.
"""

from __future__ import annotations

from collections.abc import Mapping
from typing import Any

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from app.domain.models import Instance
from app.domain.review import (
    Resolution,
    ReviewAction,
    ReviewPolicy,
    ReviewState,
    check_review_policy,
)
from app.runs import lifecycle
from app.runs.lifecycle import EventKind, RunStatus
from app.store import decision_repository as decision_repo
from app.store.models import Decision, Review, Run, utcnow


def policy_for(review: Mapping[str, Any] | None, instance: Instance) -> dict[str, Any] | None:
    """A request's review policy as the run spec stores it, checked against the instance
    (DomainError naming the field for an unknown robot, feature or task id)."""
    if review is None:
        return None
    policy = ReviewPolicy.from_json(review)
    check_review_policy(policy, instance)
    return policy.to_json()


def pause_for_review(session: Session, run: Run, payload: Mapping[str, Any]) -> None:
    """Record the review the graph paused for (once per decision, also across restarts)
    and move the run to awaiting_review, in the caller's transaction."""
    task_index = int(payload["task_index"])
    existing = session.scalar(
        select(Review).where(Review.run_id == run.id, Review.task_index == task_index)
    )
    if existing is None:
        session.add(
            Review(
                run_id=run.id,
                task_index=task_index,
                state=ReviewState.PENDING.value,
                proposal=dict(payload),
            )
        )
        session.flush()
        lifecycle.record_event(
            session,
            run_id=run.id,
            kind=EventKind.REVIEW_REQUESTED,
            detail={
                "task_index": task_index,
                "task_id": payload.get("task_id"),
                "triggers": list(payload.get("triggers", [])),
                "proposal": payload.get("proposal", {}).get("robot"),
            },
        )
    lifecycle.move(session, run, RunStatus.AWAITING_REVIEW)
    # Nobody holds a run that waits for a person: its lease (PostgreSQL scale-out) ends in
    # the same transaction, not a moment later when the worker's thread winds down.
    run.lease_owner = None
    run.lease_expires_at = None


def resolution_to_apply(session: Session, run_id: str) -> dict[str, Any] | None:
    """The resolution a worker resumes the run's graph with: a resolved review whose task
    has no stored decision yet (so a crash after it was applied never applies it twice)."""
    row = session.scalar(
        select(Review)
        .where(Review.run_id == run_id, Review.state == ReviewState.RESOLVED.value)
        .where(
            ~select(Decision.id)
            .where(Decision.run_id == run_id, Decision.task_index == Review.task_index)
            .exists()
        )
        .order_by(Review.task_index)
        .limit(1)
    )
    return None if row is None else dict(row.resolution or {})


def recorded_resolutions(*, session: Session, run_id: str) -> dict[int, Resolution]:
    """A finished run's applied reviews, by task index, as a replay re-applies them."""
    out: dict[int, Resolution] = {}
    for d in decision_repo.decisions(session=session, run_id=run_id):
        review = d.review
        if not review:
            continue
        out[d.task_index] = Resolution(
            action=ReviewAction(review["action"]),
            reviewer=str(review["reviewer"]),
            at=str(review["at"]),
            triggers=tuple(review.get("triggers") or ()),
            robot=d.robot_name if review["action"] == ReviewAction.OVERRIDE else None,
            reason=review.get("reason"),
            # An overridden team decision: the stored team is the reviewer's
            # (docs/reviews.md#reviews-of-team-decisions).
            team=tuple((m["robot"], m["feature"]) for m in d.team)
            if review["action"] == ReviewAction.OVERRIDE
            and d.team
            and "overridden_from_team" in review
            else None,
        )
    return out


def close_pending(session: Session, run_id: str, why: str) -> None:
    """Close the run's pending review (a cancel or a revision), with its event."""
    closed = session.execute(
        update(Review)
        .where(Review.run_id == run_id, Review.state == ReviewState.PENDING.value)
        .values(state=ReviewState.CLOSED.value, resolved_at=utcnow())
        .returning(Review.task_index)
        .execution_options(synchronize_session=False)
    ).all()
    for (task_index,) in closed:
        lifecycle.record_event(
            session,
            run_id=run_id,
            kind=EventKind.REVIEW_CLOSED,
            detail={"task_index": task_index, "reason": why},
        )
