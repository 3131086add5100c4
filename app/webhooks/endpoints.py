"""Webhook subscriptions and their delivery log (supervisors)."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Depends, Header, Path, Query, Request, Response, status

from app.http.deps import SettingsDep, SupervisorDep
from app.http.idempotency import KEY_PATTERN, REPLAYED_HEADER, checked_key, keyed, mark_replayed
from app.http.responses import BODY, SUPERVISOR, errors, header_schema
from app.store.idempotency import HEADER, MAX_KEY_LENGTH
from app.webhooks import service
from app.webhooks.deps import WebhooksDep
from app.webhooks.schemas import (
    WEBHOOK_ID_PATTERN,
    DeliveryOut,
    WebhookCreate,
    WebhookCreated,
    WebhookOut,
)
from app.webhooks.targets import check_subscription_url

router = APIRouter(prefix="/webhooks", tags=["webhooks"])


WebhookId = Annotated[str, Path(pattern=WEBHOOK_ID_PATTERN, description="See GET /webhooks")]
DeliveryId = Annotated[str, Path(pattern=WEBHOOK_ID_PATTERN)]


def _one_key(
    request: Request,
    key: Annotated[
        str | None,
        Header(
            alias=HEADER,
            min_length=1,
            max_length=MAX_KEY_LENGTH,
            json_schema_extra=header_schema(
                minLength=1, maxLength=MAX_KEY_LENGTH, pattern=KEY_PATTERN
            ),
            description="Makes retries safe: resending the same key with the same request "
            f"returns the first answer (secret included, `{REPLAYED_HEADER}: true`) "
            "instead of acting twice; the same key with another request is a 409.",
        ),
    ] = None,
) -> str | None:
    return checked_key(request, key)


IdempotencyKey = Annotated[str | None, Depends(_one_key)]


def _created(issued: service.Issued) -> WebhookCreated:
    return WebhookCreated(**WebhookOut.of(issued.subscription).model_dump(), secret=issued.secret)


@router.post(
    "",
    status_code=status.HTTP_201_CREATED,
    response_model=WebhookCreated,
    responses=errors(*SUPERVISOR, *BODY, 409),
)
def create_webhook(
    caller: SupervisorDep,
    body: WebhookCreate,
    webhooks: WebhooksDep,
    settings: SettingsDep,
    response: Response,
    idempotency_key: IdempotencyKey,
) -> WebhookCreated:
    """Subscribe a URL to run events; the answer holds its signing secret, once."""
    url = check_subscription_url(body.url, allow_private=settings.webhook_allow_private)
    issued, replayed = service.create_subscription(
        sessions=webhooks.sessions,
        box=webhooks.box,
        url=url,
        events=list(body.events),
        description=body.description,
        keyed=keyed(idempotency_key, body.model_dump(mode="json", exclude_unset=True)),
    )
    response.headers["Location"] = f"/webhooks/{issued.subscription.id}"
    mark_replayed(response, replayed)
    return _created(issued)


@router.get("", response_model=list[WebhookOut], responses=errors(*SUPERVISOR))
def list_webhooks(caller: SupervisorDep, webhooks: WebhooksDep) -> list[WebhookOut]:
    """Every live subscription, oldest first (secrets are never listed)."""
    return [WebhookOut.of(s) for s in service.list_subscriptions(sessions=webhooks.sessions)]


@router.get("/{webhook_id}", response_model=WebhookOut, responses=errors(*SUPERVISOR, 404))
def get_webhook(caller: SupervisorDep, webhook_id: WebhookId, webhooks: WebhooksDep) -> WebhookOut:
    return WebhookOut.of(
        service.get_subscription(sessions=webhooks.sessions, webhook_id=webhook_id)
    )


@router.delete(
    "/{webhook_id}", status_code=status.HTTP_204_NO_CONTENT, responses=errors(*SUPERVISOR, 404)
)
def delete_webhook(caller: SupervisorDep, webhook_id: WebhookId, webhooks: WebhooksDep) -> None:
    """Unsubscribe: nothing more is sent, waiting deliveries are cancelled."""
    service.delete_subscription(sessions=webhooks.sessions, webhook_id=webhook_id)


@router.post(
    "/{webhook_id}/rotate-secret",
    response_model=WebhookCreated,
    responses=errors(*SUPERVISOR, 404, 409),
)
def rotate_secret(
    caller: SupervisorDep,
    webhook_id: WebhookId,
    webhooks: WebhooksDep,
    settings: SettingsDep,
    response: Response,
    idempotency_key: IdempotencyKey,
) -> WebhookCreated:
    """Issue a new secret (shown once). The previous one keeps signing alongside it for
    LTAA_WEBHOOK_SECRET_GRACE_S (default 24 h), so receivers can switch without a gap."""
    issued, replayed = service.rotate_secret(
        sessions=webhooks.sessions,
        box=webhooks.box,
        webhook_id=webhook_id,
        grace_s=settings.webhook_secret_grace_s,
        keyed=keyed(idempotency_key, {"rotate_secret": webhook_id}),
    )
    mark_replayed(response, replayed)
    return _created(issued)


@router.get(
    "/{webhook_id}/deliveries",
    response_model=list[DeliveryOut],
    responses=errors(*SUPERVISOR, 404),
)
def list_deliveries(
    caller: SupervisorDep,
    webhook_id: WebhookId,
    webhooks: WebhooksDep,
    limit: Annotated[int, Query(ge=1, le=500)] = 50,
    offset: Annotated[int, Query(ge=0, le=1_000_000_000)] = 0,
) -> list[DeliveryOut]:
    """The delivery log, newest first: every attempt with its status code, latency, error."""
    views = service.list_deliveries(
        sessions=webhooks.sessions, webhook_id=webhook_id, limit=limit, offset=offset
    )
    return [DeliveryOut.of(v.delivery, v.attempts) for v in views]


@router.post(
    "/{webhook_id}/deliveries/{delivery_id}/retry",
    status_code=status.HTTP_202_ACCEPTED,
    response_model=DeliveryOut,
    responses=errors(*SUPERVISOR, 404, 409),
)
def retry_delivery(
    caller: SupervisorDep, webhook_id: WebhookId, delivery_id: DeliveryId, webhooks: WebhooksDep
) -> DeliveryOut:
    """Attempt a delivery now: a failed (or delivered) one gets one more attempt."""
    view = service.retry_delivery(
        sessions=webhooks.sessions, webhook_id=webhook_id, delivery_id=delivery_id
    )
    if webhooks.dispatcher is not None:
        webhooks.dispatcher.wake()
    return DeliveryOut.of(view.delivery, view.attempts)
