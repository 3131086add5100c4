"""Supervisor reviews of decisions (docs/reviews.md#which-decisions-wait-for-review): the queue of
decisions waiting for a person, and their resolution, as keyword-only functions the routes, the
console and the CLI call.

A resolution is stored with the run and queues it again in one transaction; the worker's
side of a review (pausing, resuming with the resolution) is app.runs.review_gate.
"""

from __future__ import annotations

from collections.abc import Sequence
from dataclasses import dataclass
from datetime import datetime
from typing import Any

from sqlalchemy import select, update
from sqlalchemy.orm import Session, sessionmaker

from app.domain.errors import (
    DomainError,
    IdempotencyKeyReusedError,
    RunNotFoundError,
    RunStateConflictError,
    refuse_nul,
)
from app.domain.problem import Problem
from app.domain.review import (
    Resolution,
    ReviewAction,
    ReviewState,
)
from app.graph.recorder import DecisionRecord
from app.reviews.team_override import checked_team
from app.runs import lifecycle, records
from app.runs.lifecycle import EventKind, RunStatus
from app.runs.spec import RunSpec
from app.store import decision_repository as decision_repo
from app.store import repository as repo
from app.store.db import transaction
from app.store.idempotency import Idempotency
from app.store.models import Review, Run, as_utc, utcnow


class ReviewConflictError(DomainError):
    """The review is not pending (resolved, closed, or another task's)."""

    status_code = 409
    location = "path"

    def __init__(self, run_id: str, task_index: int, why: str) -> None:
        super().__init__(
            "task_index",
            f"run '{run_id}' has no pending review of task index {task_index}: {why}. "
            "List pending reviews with GET /reviews",
            code="review_not_pending",
        )


@dataclass(frozen=True)
class PendingReview:
    """A decision waiting for a supervisor; `payload` is what the graph paused with
    (app.graph.review.review_payload), read through the properties below."""

    run_id: str
    task_index: int
    payload: dict[str, Any]
    requested_at: datetime

    @property
    def task_id(self) -> Any:
        return self.payload["task_id"]

    @property
    def task_name(self) -> str:
        return str(self.payload["task_name"])

    @property
    def proposal(self) -> dict[str, Any]:
        return dict(self.payload["proposal"])

    @property
    def triggers(self) -> list[str]:
        return list(self.payload["triggers"])

    @property
    def alternatives(self) -> list[dict[str, Any]]:
        return [dict(a) for a in self.payload["alternatives"]]

    @property
    def units(self) -> list[dict[str, Any]] | None:
        """A team decision's units (docs/reviews.md#reviews-of-team-decisions); None for one
        robot."""
        units = self.payload.get("units")
        return None if units is None else [dict(u) for u in units]


# -- the supervisor's side -----------------------------------------------------------------


def pending_reviews(*, sessions: sessionmaker[Session], limit: int = 500) -> list[PendingReview]:
    """Oldest first."""
    with sessions() as session:
        rows = session.scalars(
            select(Review)
            .where(Review.state == ReviewState.PENDING.value)
            .order_by(Review.requested_at, Review.id)
            .limit(limit)
        )
        return [
            PendingReview(
                run_id=r.run_id,
                task_index=r.task_index,
                payload=dict(r.proposal),
                requested_at=as_utc(r.requested_at),
            )
            for r in rows
        ]


@dataclass(frozen=True)
class Resolved:
    run_id: str
    task_index: int
    resolution: dict[str, Any]
    waited_s: float  # from the request to this resolution
    replayed: bool = False  # an Idempotency-Key retry of the resolution that won


def resolve(
    *,
    sessions: sessionmaker[Session],
    run_id: str,
    task_index: int,
    action: ReviewAction,
    robot: str | None,
    reason: str | None,
    reviewer: str,
    idempotency: Idempotency | None = None,
    team: Sequence[tuple[str, str]] | None = None,
) -> Resolved:
    """Store the resolution and queue the run again, in one transaction: of two concurrent
    resolutions the conditional UPDATE lets exactly one through (the other: 409). A retry
    with the Idempotency-Key of the resolution that won gets its answer again."""
    reason = (reason or "").strip() or None
    refuse_nul("reason", reason)
    if action is ReviewAction.OVERRIDE and reason is None:
        raise DomainError("reason", "an override needs a reason", code="missing")
    if action is ReviewAction.OVERRIDE and robot is None and team is None:
        raise DomainError("robot", "an override names the robot to use", code="missing")
    if action is ReviewAction.APPROVE and (robot is not None or team is not None):
        raise DomainError(
            "robot" if team is None else "team",
            "an approval takes the proposal; send action 'override'",
            code="invalid",
        )
    with sessions() as session:
        run = repo.get_run(session=session, run_id=run_id)
        if run is None:
            raise RunNotFoundError(run_id)
        review = session.scalar(
            select(Review).where(Review.run_id == run_id, Review.task_index == task_index)
        )
        if review is None:
            raise ReviewConflictError(run_id, task_index, "the run never paused for it")
        earlier = _retried(review, idempotency)
        if earlier is not None:
            return earlier
        if review.state != ReviewState.PENDING:
            raise ReviewConflictError(run_id, task_index, f"it is {review.state}")
        payload = dict(review.proposal)
        team_run = _team_run(session, run, payload) if action is ReviewAction.OVERRIDE else None
    units = _checked_choice(payload, task_index, action, robot, team, team_run)
    now = utcnow()
    resolution = Resolution(
        action=action,
        reviewer=reviewer,
        at=now.isoformat(),
        triggers=tuple(payload.get("triggers", [])),
        robot=robot if units is None else units[0][0],
        reason=reason,
        team=None if units is None else tuple(units),
    ).to_json()
    with transaction(sessions) as session:
        # The first statement writes: on SQLite it takes the write lock at once (a stale read
        # snapshot cannot be upgraded), on PostgreSQL it locks the row; either way the
        # state check and the write are one step, so exactly one resolution wins.
        won = session.execute(
            update(Review)
            .where(
                Review.run_id == run_id,
                Review.task_index == task_index,
                Review.state == ReviewState.PENDING.value,
            )
            .values(
                state=ReviewState.RESOLVED.value,
                resolution=resolution,
                resolved_at=now,
                idempotency_key=idempotency.key if idempotency else None,
                request_digest=idempotency.digest if idempotency else None,
            )
            .returning(Review.requested_at)
            .execution_options(synchronize_session=False)
        ).first()
        if won is None:
            raise ReviewConflictError(run_id, task_index, "another resolution came first")
        if not lifecycle.move_where(
            session, run_id=run_id, current=RunStatus.AWAITING_REVIEW, to=RunStatus.QUEUED
        ):
            raise RunStateConflictError(run_id, "not awaiting review", "resolve a review", "")
        lifecycle.record_event(
            session,
            run_id=run_id,
            kind=EventKind.REVIEW_RESOLVED,
            detail={"task_index": task_index, **resolution},
        )
    waited = (now - as_utc(won.requested_at)).total_seconds()
    return Resolved(run_id=run_id, task_index=task_index, resolution=resolution, waited_s=waited)


def _team_run(
    session: Session, run: Run, payload: dict[str, Any]
) -> tuple[Problem, list[DecisionRecord]] | None:
    """What a team override is checked against (docs/reviews.md#reviews-of-team-decisions): the
    problem the run decides (a guided timed run's in its plan's order) and its decisions so
    far (a timed run's time lines); None for a one-robot decision."""
    if "team" not in payload["proposal"]:
        return None
    spec = RunSpec.from_json(run.request)
    problem = records.run_problem(session, run.id, spec.problem, spec.guidance)
    made = [
        records.decision_record(d) for d in decision_repo.decisions(session=session, run_id=run.id)
    ]
    return problem, made


def _checked_choice(
    payload: dict[str, Any],
    task_index: int,
    action: ReviewAction,
    robot: str | None,
    team: Sequence[tuple[str, str]] | None,
    team_run: tuple[Problem, list[DecisionRecord]] | None,
) -> list[tuple[str, str]] | None:
    """An override's robot, checked against the alternatives the review listed, or its team
    (docs/reviews.md#reviews-of-team-decisions) as (robot, feature) per unit; None but for a
    team."""
    if action is ReviewAction.APPROVE:
        return None  # the proposal as it stands, one robot or a team
    if team_run is not None:
        problem, made = team_run
        return checked_team(problem, payload, task_index, robot, team, made)
    if team is not None:
        raise DomainError(
            "team",
            f"task index {task_index} is a one-robot decision; an override sends `robot`",
            code="not_a_team",
        )
    alternatives = {a["robot"]: a for a in payload["alternatives"]}
    if robot not in alternatives:
        raise DomainError(
            "robot",
            f"unknown robot '{robot}'; the run's robots are: {', '.join(alternatives)}",
            code="unknown_robot",
        )
    if not alternatives[robot]["cap_feasible"]:
        raise DomainError(
            "robot",
            f"robot '{robot}' cannot take task index {task_index}: the workload cap "
            "could no longer be met",
            code="cap_infeasible",
        )
    return None


def _retried(review: Review, idempotency: Idempotency | None) -> Resolved | None:
    """The stored answer, if this request repeats the one that resolved the review."""
    if idempotency is None or review.idempotency_key != idempotency.key:
        return None
    if review.request_digest != idempotency.digest:
        raise IdempotencyKeyReusedError.for_run(review.run_id)
    return Resolved(
        run_id=review.run_id,
        task_index=review.task_index,
        resolution=dict(review.resolution or {}),
        waited_s=0.0,
        replayed=True,
    )
