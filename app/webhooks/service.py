"""Subscription commands and views, as keyword-only functions the routes call."""

from __future__ import annotations

import hashlib
import json
import uuid
from dataclasses import dataclass
from datetime import timedelta
from typing import Protocol

from sqlalchemy.exc import IntegrityError
from sqlalchemy.orm import Session, sessionmaker

from app.domain.errors import IdempotencyKeyReusedError
from app.store.db import transaction
from app.store.models import utcnow
from app.store.webhook_models import (
    WebhookAttempt,
    WebhookDelivery,
    WebhookSecret,
    WebhookSubscription,
)
from app.webhooks import repository
from app.webhooks.errors import (
    DeliveryNotFoundError,
    DeliveryStateConflictError,
    DuplicateSubscriptionError,
)
from app.webhooks.events import ALL
from app.webhooks.queue import db_now
from app.webhooks.secret_box import SecretBox, new_secret
from app.webhooks.status import DeliveryState


class Keyed(Protocol):
    """An Idempotency-Key and the digest of the request it came with (the API's
    Idempotency; structural, since webhooks do not import runs)."""

    @property
    def key(self) -> str: ...

    @property
    def digest(self) -> str: ...


@dataclass(frozen=True)
class Issued:
    """A subscription with a secret in plain text: the one answer that shows it."""

    subscription: WebhookSubscription
    secret: str


def normalise_events(events: list[str]) -> list[str]:
    """Sorted and deduplicated; `*` alone stands for every type."""
    return [ALL] if ALL in events else sorted(set(events))


def dedupe_key(url: str, events: list[str]) -> str:
    return hashlib.sha256(json.dumps([url, events]).encode("utf-8")).hexdigest()


def _current_secret(session: Session, box: SecretBox, webhook_id: str) -> str:
    ciphertext = repository.newest_ciphertext(session=session, webhook_id=webhook_id)
    return box.decrypt(ciphertext) if ciphertext else ""


def create_subscription(
    *,
    sessions: sessionmaker[Session],
    box: SecretBox,
    url: str,
    events: list[str],
    description: str,
    keyed: Keyed | None,
) -> tuple[Issued, bool]:
    """(the subscription and its secret, whether an earlier request with the same
    Idempotency-Key created it). A retry gets the answer the first request got, secret
    included: a client whose first response was lost still learns it."""
    events = normalise_events(events)
    secret = new_secret()
    sub_id = f"wh_{uuid.uuid4().hex}"
    try:
        with transaction(sessions) as session:
            sub = WebhookSubscription(
                id=sub_id,
                url=url,
                events=events,
                description=description,
                created_at=utcnow(),
                dedupe_key=dedupe_key(url, events),
                idempotency_key=keyed.key if keyed else None,
                request_digest=keyed.digest if keyed else None,
            )
            session.add(sub)
            session.flush()
            session.add(WebhookSecret(subscription_id=sub_id, ciphertext=box.encrypt(secret)))
        return Issued(sub, secret), False
    except IntegrityError:
        # The unique indexes arbitrate (two identical requests at once end the same way).
        pass
    with sessions() as session:
        if keyed is not None:
            earlier = repository.subscription_by_key(session=session, key=keyed.key)
            if earlier is not None:
                if earlier.request_digest != keyed.digest:
                    raise IdempotencyKeyReusedError(f"it created webhook '{earlier.id}'")
                return Issued(earlier, _current_secret(session, box, earlier.id)), True
        duplicate = repository.subscription_id_by_dedupe_key(
            session=session, dedupe_key=dedupe_key(url, events)
        )
    if duplicate is not None:
        raise DuplicateSubscriptionError(duplicate)
    raise RuntimeError("webhook subscription insert failed on an unexpected constraint")


def list_subscriptions(*, sessions: sessionmaker[Session]) -> list[WebhookSubscription]:
    with sessions() as session:
        return repository.live_subscriptions(session=session)


def get_subscription(*, sessions: sessionmaker[Session], webhook_id: str) -> WebhookSubscription:
    with sessions() as session:
        return repository.live_subscription(session=session, webhook_id=webhook_id)


def delete_subscription(*, sessions: sessionmaker[Session], webhook_id: str) -> None:
    """Stop sending: undelivered deliveries are cancelled; the log stays readable to the
    database, not through the API."""
    with transaction(sessions) as session:
        sub = repository.live_subscription(session=session, webhook_id=webhook_id)
        sub.deleted_at = utcnow()
        sub.dedupe_key = None
        repository.cancel_pending_deliveries(session=session, webhook_id=webhook_id)


def rotate_secret(
    *,
    sessions: sessionmaker[Session],
    box: SecretBox,
    webhook_id: str,
    grace_s: float,
    keyed: Keyed | None,
) -> tuple[Issued, bool]:
    """Issue a new secret; the ones it replaces keep signing for `grace_s` seconds."""
    secret = new_secret()
    try:
        with transaction(sessions) as session:
            sub = repository.live_subscription(session=session, webhook_id=webhook_id)
            repository.expire_open_secrets(
                session=session, webhook_id=webhook_id, expires_at=db_now(session, grace_s)
            )
            session.add(
                WebhookSecret(
                    subscription_id=webhook_id,
                    ciphertext=box.encrypt(secret),
                    idempotency_key=keyed.key if keyed else None,
                    request_digest=keyed.digest if keyed else None,
                )
            )
        return Issued(sub, secret), False
    except IntegrityError:
        if keyed is None:
            raise
    with sessions() as session:
        earlier = repository.secret_by_key(session=session, key=keyed.key)
        if earlier is None:
            raise RuntimeError("secret rotation failed on an unexpected constraint")
        if earlier.subscription_id != webhook_id or earlier.request_digest != keyed.digest:
            raise IdempotencyKeyReusedError(
                f"it rotated the secret of webhook '{earlier.subscription_id}'"
            )
        return Issued(
            repository.live_subscription(session=session, webhook_id=webhook_id),
            box.decrypt(earlier.ciphertext),
        ), True


@dataclass
class DeliveryView:
    delivery: WebhookDelivery
    attempts: list[WebhookAttempt]


def list_deliveries(
    *, sessions: sessionmaker[Session], webhook_id: str, limit: int, offset: int
) -> list[DeliveryView]:
    """Newest first, each with every attempt (oldest first)."""
    with sessions() as session:
        repository.live_subscription(session=session, webhook_id=webhook_id)
        deliveries = repository.deliveries_page(
            session=session, webhook_id=webhook_id, limit=limit, offset=offset
        )
        by_delivery: dict[str, list[WebhookAttempt]] = {d.id: [] for d in deliveries}
        for attempt in repository.attempts_of(session=session, delivery_ids=list(by_delivery)):
            by_delivery[attempt.delivery_id].append(attempt)
    return [DeliveryView(d, by_delivery[d.id]) for d in deliveries]


def retry_delivery(
    *, sessions: sessionmaker[Session], webhook_id: str, delivery_id: str
) -> DeliveryView:
    """Attempt now. A delivered or failed delivery gets one more attempt (its schedule is
    spent); a waiting one is simply brought forward."""
    with transaction(sessions) as session:
        repository.live_subscription(session=session, webhook_id=webhook_id)
        delivery = session.get(WebhookDelivery, delivery_id, with_for_update=True)
        if delivery is None or delivery.subscription_id != webhook_id:
            raise DeliveryNotFoundError(webhook_id, delivery_id)
        if delivery.state == DeliveryState.CANCELLED:
            raise DeliveryStateConflictError(delivery_id, str(delivery.state))
        if delivery.state != DeliveryState.PENDING:
            delivery.manual_retry = True
            delivery.state = DeliveryState.PENDING
            delivery.finished_at = None
        delivery.next_attempt_at = utcnow() - timedelta(seconds=1)
        session.flush()
        attempts = repository.attempts_of(session=session, delivery_ids=[delivery_id])
    return DeliveryView(delivery, attempts)


def reencrypt_secrets(*, sessions: sessionmaker[Session], box: SecretBox) -> int:
    """Re-encrypt every stored secret under the first server key (after a new key was put
    first in LTAA_SECRET_KEY); the old key may then be dropped. Returns how many rows."""
    with transaction(sessions) as session:
        rows = repository.secrets_for_update(session=session)
        for row in rows:
            row.ciphertext = box.rotate(row.ciphertext)
    return len(rows)
