"""The subscription tables' queries (subscriptions, their secrets, the delivery log), as
keyword-only functions over a session the caller's transaction owns.

The webhooks feature owns these tables alone; the models stay with the others in
`app/store/webhook_models.py` (one metadata for the migrations). The delivery queue's own
queries (claiming, attempts) are `queue.py`."""

from __future__ import annotations

from collections.abc import Sequence
from typing import Any

from sqlalchemy import select, update
from sqlalchemy.orm import Session

from app.store.models import utcnow
from app.store.webhook_models import (
    WebhookAttempt,
    WebhookDelivery,
    WebhookSecret,
    WebhookSubscription,
)
from app.webhooks.errors import WebhookNotFoundError
from app.webhooks.status import DeliveryState


def live_subscription(*, session: Session, webhook_id: str) -> WebhookSubscription:
    """The subscription, unless it does not exist or was deleted (WebhookNotFoundError)."""
    sub = session.get(WebhookSubscription, webhook_id)
    if sub is None or sub.deleted_at is not None:
        raise WebhookNotFoundError(webhook_id)
    return sub


def live_subscriptions(*, session: Session) -> list[WebhookSubscription]:
    """Every subscription not deleted, oldest first."""
    return list(
        session.scalars(
            select(WebhookSubscription)
            .where(WebhookSubscription.deleted_at.is_(None))
            .order_by(WebhookSubscription.created_at, WebhookSubscription.id)
        )
    )


def subscription_by_key(*, session: Session, key: str) -> WebhookSubscription | None:
    """The subscription an Idempotency-Key created, if any."""
    return session.scalar(
        select(WebhookSubscription).where(WebhookSubscription.idempotency_key == key)
    )


def subscription_id_by_dedupe_key(*, session: Session, dedupe_key: str) -> str | None:
    """The live subscription with the same URL and events, if any."""
    return session.scalar(
        select(WebhookSubscription.id).where(WebhookSubscription.dedupe_key == dedupe_key)
    )


def newest_ciphertext(*, session: Session, webhook_id: str) -> str | None:
    """The subscription's newest secret, encrypted as stored."""
    return session.scalar(
        select(WebhookSecret.ciphertext)
        .where(WebhookSecret.subscription_id == webhook_id)
        .order_by(WebhookSecret.id.desc())
        .limit(1)
    )


def secret_by_key(*, session: Session, key: str) -> WebhookSecret | None:
    """The secret an Idempotency-Key's rotation issued, if any."""
    return session.scalar(select(WebhookSecret).where(WebhookSecret.idempotency_key == key))


def expire_open_secrets(*, session: Session, webhook_id: str, expires_at: Any) -> None:
    """Give every secret without an end this one (a rotation's grace period)."""
    session.execute(
        update(WebhookSecret)
        .where(
            WebhookSecret.subscription_id == webhook_id,
            WebhookSecret.expires_at.is_(None),
        )
        .values(expires_at=expires_at)
        .execution_options(synchronize_session=False)
    )


def secrets_for_update(*, session: Session) -> list[WebhookSecret]:
    """Every stored secret, locked for the re-encryption that rewrites them."""
    return list(session.scalars(select(WebhookSecret).with_for_update()))


def cancel_pending_deliveries(*, session: Session, webhook_id: str) -> None:
    """A deleted subscription's undelivered messages are never sent."""
    session.execute(
        update(WebhookDelivery)
        .where(
            WebhookDelivery.subscription_id == webhook_id,
            WebhookDelivery.state == DeliveryState.PENDING,
        )
        .values(state=DeliveryState.CANCELLED, finished_at=utcnow())
        .execution_options(synchronize_session=False)
    )


def deliveries_page(
    *, session: Session, webhook_id: str, limit: int, offset: int
) -> list[WebhookDelivery]:
    """A page of the subscription's deliveries, newest first."""
    return list(
        session.scalars(
            select(WebhookDelivery)
            .where(WebhookDelivery.subscription_id == webhook_id)
            .order_by(WebhookDelivery.created_at.desc(), WebhookDelivery.id)
            .limit(limit)
            .offset(offset)
        )
    )


def attempts_of(*, session: Session, delivery_ids: Sequence[str]) -> list[WebhookAttempt]:
    """Every attempt of these deliveries, oldest first."""
    if not delivery_ids:
        return []
    return list(
        session.scalars(
            select(WebhookAttempt)
            .where(WebhookAttempt.delivery_id.in_(list(delivery_ids)))
            .order_by(WebhookAttempt.attempt)
        )
    )
