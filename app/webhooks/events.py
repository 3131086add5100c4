"""The webhook event types (SPEC 12) and which run event kinds produce them."""

from __future__ import annotations

from enum import StrEnum

ALL = "*"


class WebhookEventType(StrEnum):
    RUN_CREATED = "run.created"
    RUN_COMPLETED = "run.completed"
    RUN_FAILED = "run.failed"
    RUN_CANCELLED = "run.cancelled"
    RUN_INTERRUPTED = "run.interrupted"
    RUN_SUPERSEDED = "run.superseded"
    RUN_REVISED = "run.revised"
    REVIEW_REQUESTED = "review.requested"
    REVIEW_RESOLVED = "review.resolved"
    RUN_SIGNED_OFF = "run.signed_off"
    BUDGET_EXHAUSTED = "budget.exhausted"


# Run event kind -> webhook type. Kinds absent here (started, resumed, ...) send nothing.
# Features that add event kinds (revisions, reviews, sign-off) add their rows here.
TYPE_OF_KIND: dict[str, WebhookEventType] = {
    "created": WebhookEventType.RUN_CREATED,
    "completed": WebhookEventType.RUN_COMPLETED,
    "failed": WebhookEventType.RUN_FAILED,
    "integrity_failed": WebhookEventType.RUN_FAILED,
    "cancelled": WebhookEventType.RUN_CANCELLED,
    "interrupted": WebhookEventType.RUN_INTERRUPTED,
    "budget_exhausted": WebhookEventType.BUDGET_EXHAUSTED,
    "superseded": WebhookEventType.RUN_SUPERSEDED,
    "revised": WebhookEventType.RUN_REVISED,
    "review_requested": WebhookEventType.REVIEW_REQUESTED,
    "review_resolved": WebhookEventType.REVIEW_RESOLVED,
    "signed_off": WebhookEventType.RUN_SIGNED_OFF,
}

# The run status a kind leaves the run in, for the payload's `data.status`.
STATUS_OF_KIND: dict[str, str] = {
    "created": "queued",
    "completed": "completed",
    "failed": "failed",
    "integrity_failed": "failed",
    "cancelled": "cancelled",
    "interrupted": "interrupted",
}


def subscribed(events: list[str], event_type: WebhookEventType) -> bool:
    return ALL in events or event_type.value in events
