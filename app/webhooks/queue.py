"""The delivery queue in the database: claim what is due, record each attempt.

A claim is a lease: `claimed_by` and `claim_expires_at` (database clock on PostgreSQL).
Claims take rows with `FOR UPDATE SKIP LOCKED`, so concurrent dispatchers (processes) each
get different deliveries and never wait; a claim outlives the HTTP timeout, so a live
process always records its attempt before anyone else may try. A process that died with
a delivery in flight leaves a claim that expires, and another process retries it. Results
are written only while the claim is still the writer's (fencing).
"""

from __future__ import annotations

import random
from dataclasses import dataclass
from datetime import datetime, timedelta
from typing import Any

from sqlalchemy import func, or_, select, update
from sqlalchemy.orm import Session

from app.store.models import utcnow
from app.store.webhook_models import WebhookAttempt, WebhookDelivery, WebhookSecret
from app.webhooks.status import AttemptOutcome, DeliveryState

D = WebhookDelivery
JITTER = 0.2  # each delay is stretched or shrunk by up to 20%, so retries do not stampede


def db_now(session: Session, plus_s: float = 0.0) -> Any:
    """Now, from the database clock on PostgreSQL (processes on skewed hosts agree on
    when a claim expires); SQLite has one process, whose clock is the clock."""
    if session.get_bind().dialect.name == "postgresql":
        return func.now() + timedelta(seconds=plus_s)
    return utcnow() + timedelta(seconds=plus_s)


def _no_sync(stmt: Any) -> Any:
    return stmt.execution_options(synchronize_session=False)


@dataclass(frozen=True)
class Claimed:
    id: str
    attempt: int
    subscription_id: str
    payload: str


def claim_due(*, session: Session, owner: str, claim_s: float, limit: int) -> list[Claimed]:
    """Lease up to `limit` pending deliveries that are due and unclaimed, oldest due first;
    each claim counts as the delivery's next attempt."""
    if limit <= 0:
        return []
    now = db_now(session)
    ids = list(
        session.scalars(
            select(D.id)
            .where(
                D.state == DeliveryState.PENDING,
                D.next_attempt_at <= now,
                or_(D.claim_expires_at.is_(None), D.claim_expires_at < now),
            )
            .order_by(D.next_attempt_at, D.id)
            .limit(limit)
            .with_for_update(skip_locked=True)
        )
    )
    if not ids:
        return []
    rows = session.execute(
        _no_sync(
            update(D)
            .where(D.id.in_(ids))
            .values(
                claimed_by=owner,
                claim_expires_at=db_now(session, claim_s),
                attempts=D.attempts + 1,
            )
            .returning(D.id, D.attempts, D.subscription_id, D.payload)
        )
    ).all()
    return [Claimed(r.id, r.attempts, r.subscription_id, r.payload) for r in rows]


def live_ciphertexts(*, session: Session, subscription_id: str) -> list[str]:
    """The secrets that sign now, newest first: the current one and rotated-out ones
    still in their grace period."""
    now = db_now(session)
    return list(
        session.scalars(
            select(WebhookSecret.ciphertext)
            .where(
                WebhookSecret.subscription_id == subscription_id,
                or_(WebhookSecret.expires_at.is_(None), WebhookSecret.expires_at > now),
            )
            .order_by(WebhookSecret.id.desc())
        )
    )


@dataclass(frozen=True)
class AttemptResult:
    outcome: AttemptOutcome
    started_at: datetime
    latency_ms: float
    status_code: int | None = None
    error: str | None = None
    response_excerpt: str | None = None


def next_delay(delays: list[float], attempt: int, rng: random.Random) -> float | None:
    """Seconds until the attempt after `attempt` (1-based), or None: it was the last."""
    if attempt > len(delays):
        return None
    return delays[attempt - 1] * rng.uniform(1 - JITTER, 1 + JITTER)


def record_attempt(
    *,
    session: Session,
    claimed: Claimed,
    owner: str,
    result: AttemptResult,
    delay_s: float | None,
) -> str | None:
    """Log the attempt; move the delivery on if this process still holds its claim. The
    delivery's new status, or None when the claim had passed to another process."""
    session.add(
        WebhookAttempt(
            delivery_id=claimed.id,
            attempt=claimed.attempt,
            started_at=result.started_at,
            latency_ms=result.latency_ms,
            outcome=result.outcome,
            status_code=result.status_code,
            error=result.error,
            response_excerpt=result.response_excerpt,
            worker=owner,
        )
    )
    delivery = session.get(D, claimed.id, with_for_update=True)
    if delivery is None or delivery.claimed_by != owner or delivery.attempts != claimed.attempt:
        return None
    delivery.claimed_by = None
    delivery.claim_expires_at = None
    delivery.last_status_code = result.status_code
    delivery.last_error = result.error
    if result.outcome is AttemptOutcome.DELIVERED:
        delivery.state = DeliveryState.DELIVERED
        delivery.finished_at = utcnow()
        delivery.last_error = None
    elif delay_s is None or delivery.manual_retry:
        delivery.state = DeliveryState.FAILED
        delivery.finished_at = utcnow()
    else:
        delivery.next_attempt_at = db_now(session, delay_s)
    delivery.manual_retry = False
    return str(delivery.state)


def release_all_claims(*, session: Session) -> int:
    """Start-up on SQLite, the one-process store: claims left in the table belong to a
    process that died (it holds the store lock no more), so they are retried now rather
    than when they expire."""
    result = session.execute(
        _no_sync(
            update(D)
            .where(D.claimed_by.is_not(None))
            .values(claimed_by=None, claim_expires_at=None)
        )
    )
    return int(getattr(result, "rowcount", 0) or 0)
