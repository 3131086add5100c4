"""The webhook event types (docs/webhooks.md#event-types-and-payloads) and which run event kinds
produce them."""

from __future__ import annotations

from enum import StrEnum

from app.domain.lifecycle import EventKind, RunStatus

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
    LLM_GAVE_UP = "llm.gave_up"


# Run event kind -> webhook type. Kinds absent here (started, resumed, ...) send nothing.
# A sign-off is an annotation, not a run event (a completed run's events never change):
# app.runs.lifecycle.record_annotation enqueues it under this kind.
SIGNED_OFF = "signed_off"

TYPE_OF_KIND: dict[str, WebhookEventType] = {
    EventKind.CREATED: WebhookEventType.RUN_CREATED,
    EventKind.COMPLETED: WebhookEventType.RUN_COMPLETED,
    EventKind.FAILED: WebhookEventType.RUN_FAILED,
    EventKind.INTEGRITY_FAILED: WebhookEventType.RUN_FAILED,
    EventKind.CANCELLED: WebhookEventType.RUN_CANCELLED,
    EventKind.INTERRUPTED: WebhookEventType.RUN_INTERRUPTED,
    EventKind.BUDGET_EXHAUSTED: WebhookEventType.BUDGET_EXHAUSTED,
    EventKind.LLM_GAVE_UP: WebhookEventType.LLM_GAVE_UP,
    EventKind.SUPERSEDED: WebhookEventType.RUN_SUPERSEDED,
    EventKind.REVISED: WebhookEventType.RUN_REVISED,
    EventKind.REVIEW_REQUESTED: WebhookEventType.REVIEW_REQUESTED,
    EventKind.REVIEW_RESOLVED: WebhookEventType.REVIEW_RESOLVED,
    SIGNED_OFF: WebhookEventType.RUN_SIGNED_OFF,
}

# The run status a kind leaves the run in, for the payload's `data.status`.
STATUS_OF_KIND: dict[str, RunStatus] = {
    EventKind.CREATED: RunStatus.QUEUED,
    EventKind.COMPLETED: RunStatus.COMPLETED,
    EventKind.FAILED: RunStatus.FAILED,
    EventKind.INTEGRITY_FAILED: RunStatus.FAILED,
    EventKind.CANCELLED: RunStatus.CANCELLED,
    EventKind.INTERRUPTED: RunStatus.INTERRUPTED,
    EventKind.REVIEW_REQUESTED: RunStatus.AWAITING_REVIEW,
    EventKind.REVIEW_RESOLVED: RunStatus.QUEUED,
    EventKind.SUPERSEDED: RunStatus.SUPERSEDED,
}


def subscribed(events: list[str], event_type: WebhookEventType) -> bool:
    return ALL in events or event_type.value in events
