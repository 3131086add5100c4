"""Bodies of the /webhooks endpoints."""

from __future__ import annotations

import json
from typing import Annotated, Any, Literal, get_args

from pydantic import BaseModel, ConfigDict, Field

from app.http.fields import NoNul
from app.http.times import Timestamp
from app.store.webhook_models import WebhookAttempt, WebhookDelivery, WebhookSubscription
from app.webhooks.events import ALL, WebhookEventType
from app.webhooks.targets import MAX_URL_CHARS

EventName = Literal[
    "*",
    "run.created",
    "run.completed",
    "run.failed",
    "run.cancelled",
    "run.interrupted",
    "run.superseded",
    "run.revised",
    "review.requested",
    "review.resolved",
    "run.signed_off",
    "budget.exhausted",
    "llm.gave_up",
]
# One list of names: the Literal (for the OpenAPI enum) is the enum plus "*".
assert set(get_args(EventName)) == {ALL, *WebhookEventType}

DeliveryStateName = Literal["pending", "delivered", "failed", "cancelled"]
WEBHOOK_ID_PATTERN = r"^[A-Za-z0-9_-]+$"


class WebhookCreate(BaseModel):
    model_config = ConfigDict(
        extra="forbid",
        json_schema_extra={
            "examples": [
                {
                    "url": "https://site.example.com/ltaa-hooks",
                    "events": ["run.completed", "run.failed"],
                    "description": "site planning board",
                }
            ]
        },
    )

    url: str = Field(
        min_length=1,
        max_length=MAX_URL_CHARS,
        description="Where to POST events: an http(s) URL; private addresses only with "
        "LTAA_WEBHOOK_ALLOW_PRIVATE=true",
    )
    events: list[EventName] = Field(
        min_length=1, max_length=32, description='Event types, or ["*"] for every type'
    )
    description: Annotated[str, NoNul] = Field("", max_length=500)


class WebhookOut(BaseModel):
    id: str
    url: str
    events: list[str]
    description: str
    created_at: Timestamp

    @classmethod
    def of(cls, row: WebhookSubscription) -> WebhookOut:
        return cls(
            id=row.id,
            url=row.url,
            events=list(row.events),
            description=row.description,
            created_at=row.created_at,
        )


class WebhookCreated(WebhookOut):
    secret: str = Field(
        description="`whsec_...`: verify signatures with it (Standard Webhooks). Shown in "
        "this answer only (and to a retry with the same Idempotency-Key)"
    )


class AttemptOut(BaseModel):
    attempt: int
    started_at: Timestamp
    latency_ms: float
    outcome: str = Field(
        description="delivered | http_error | network_error | refused | secret_error"
    )
    status_code: int | None
    error: str | None
    response_excerpt: str | None
    worker: str

    @classmethod
    def of(cls, row: WebhookAttempt) -> AttemptOut:
        return cls(
            attempt=row.attempt,
            started_at=row.started_at,
            latency_ms=row.latency_ms,
            outcome=row.outcome,
            status_code=row.status_code,
            error=row.error,
            response_excerpt=row.response_excerpt,
            worker=row.worker,
        )


class DeliveryOut(BaseModel):
    id: str = Field(description="The `webhook-id` header: the same on every attempt")
    event_type: str
    run_id: str
    status: DeliveryStateName
    attempts: int
    next_attempt_at: Timestamp | None = Field(description="While pending: when it is due")
    last_status_code: int | None
    last_error: str | None
    created_at: Timestamp
    finished_at: Timestamp | None
    payload: dict[str, Any]
    attempt_log: list[AttemptOut]

    @classmethod
    def of(cls, row: WebhookDelivery, attempts: list[WebhookAttempt]) -> DeliveryOut:
        return cls(
            id=row.id,
            event_type=row.event_type,
            run_id=row.run_id,
            status=row.state,  # type: ignore[arg-type]
            attempts=row.attempts,
            next_attempt_at=row.next_attempt_at if row.state == "pending" else None,
            last_status_code=row.last_status_code,
            last_error=row.last_error,
            created_at=row.created_at,
            finished_at=row.finished_at,
            payload=json.loads(row.payload),
            attempt_log=[AttemptOut.of(a) for a in attempts],
        )
