"""The outbox: deliveries written in the transaction of the run event they report.

`enqueue_for_event` is called by the one function that writes run events, with the same
session, so the event and its deliveries commit or roll back together: a crash after the
commit leaves deliveries for the dispatcher to send (after a restart, if need be), and a
crash before leaves neither. Delivery is then at least once.
"""

from __future__ import annotations

import json
import uuid
from datetime import UTC, datetime
from typing import Any

from sqlalchemy import func, select
from sqlalchemy.orm import Session

from app.domain.lifecycle import EventKind
from app.store.models import Decision, utcnow
from app.store.webhook_models import WebhookDelivery, WebhookSubscription
from app.webhooks.events import STATUS_OF_KIND, TYPE_OF_KIND, WebhookEventType, subscribed
from app.webhooks.status import DeliveryState


def new_message_id() -> str:
    return f"msg_{uuid.uuid4().hex}"


def rfc3339(at: datetime) -> str:
    aware = at if at.tzinfo is not None else at.replace(tzinfo=UTC)
    return aware.astimezone(UTC).isoformat(timespec="milliseconds").replace("+00:00", "Z")


def _data(
    session: Session, *, run_id: str, kind: str, detail: dict[str, Any], seq: int
) -> dict[str, Any]:
    data: dict[str, Any] = {**detail, "run_id": run_id, "event": kind, "seq": seq}
    if kind in STATUS_OF_KIND:
        data["status"] = STATUS_OF_KIND[kind].value
    if kind == EventKind.COMPLETED:
        # The run's expected success: the mean success of the stored decisions
        # (docs/allocation.md#success-and-balance), read in this transaction, so it is exactly what
        # the completed run holds.
        count, total = session.execute(
            select(func.count(), func.coalesce(func.sum(Decision.expected_success), 0.0)).where(
                Decision.run_id == run_id
            )
        ).one()
        data["decisions"] = int(count)
        data["expected_success"] = float(total) / count if count else None
    return data


def payload(event_type: WebhookEventType, at: datetime, data: dict[str, Any]) -> str:
    body = {"type": event_type.value, "timestamp": rfc3339(at), "data": data}
    return json.dumps(body, separators=(",", ":"), ensure_ascii=False, allow_nan=False)


def enqueue_for_event(
    session: Session,
    *,
    run_id: str,
    kind: str,
    detail: dict[str, Any],
    seq: int,
    at: datetime | None = None,
    annotation: bool = False,
) -> list[WebhookDelivery]:
    """One pending delivery per live subscription to this event's webhook type that was
    created before the event; nothing for kinds no webhook type reports.

    `annotation`: `seq` numbers the run's annotation chain (a sign-off), not its events.
    Such a delivery is keyed by the negated number, so it can never take the outbox slot
    (subscription, run, event_seq) of the run event with the same number."""
    event_type = TYPE_OF_KIND.get(str(kind))
    if event_type is None:
        return []
    at = at or utcnow()
    subscriptions = [
        s
        for s in session.scalars(
            select(WebhookSubscription)
            .where(WebhookSubscription.deleted_at.is_(None), WebhookSubscription.created_at <= at)
            .order_by(WebhookSubscription.created_at, WebhookSubscription.id)
        )
        if subscribed(list(s.events), event_type)
    ]
    if not subscriptions:
        return []
    body = payload(
        event_type, at, _data(session, run_id=run_id, kind=str(kind), detail=detail, seq=seq)
    )
    deliveries = [
        WebhookDelivery(
            id=new_message_id(),
            subscription_id=s.id,
            event_type=event_type.value,
            run_id=run_id,
            event_seq=-seq if annotation else seq,
            payload=body,
            state=DeliveryState.PENDING,
            attempts=0,
            manual_retry=False,
            next_attempt_at=at,
            created_at=at,
        )
        for s in subscriptions
    ]
    session.add_all(deliveries)
    return deliveries
