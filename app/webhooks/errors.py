"""Webhook errors, shaped like domain errors so the API answers them in the one 4xx shape."""

from __future__ import annotations

from app.domain.errors import DomainError, NotFoundError, StateConflictError


class WebhookNotFoundError(NotFoundError):
    def __init__(self, webhook_id: str) -> None:
        super().__init__(
            "webhook_id",
            f"no webhook subscription with id '{webhook_id}'; list them with GET /webhooks",
        )


class DeliveryNotFoundError(NotFoundError):
    def __init__(self, webhook_id: str, delivery_id: str) -> None:
        super().__init__(
            "delivery_id",
            f"webhook '{webhook_id}' has no delivery '{delivery_id}'; "
            f"see GET /webhooks/{webhook_id}/deliveries",
        )


class DuplicateSubscriptionError(DomainError):
    status_code = 409

    def __init__(self, existing_id: str) -> None:
        super().__init__(
            "url",
            f"webhook '{existing_id}' already sends these events to this URL; delete it "
            "first or subscribe to other events",
            code="duplicate_subscription",
        )


class DeliveryStateConflictError(StateConflictError):
    def __init__(self, delivery_id: str, status: str) -> None:
        super().__init__(
            "delivery_id",
            f"delivery '{delivery_id}' is {status}; only a delivered, failed or waiting "
            "delivery can be retried",
        )


class SecretKeyError(ValueError):
    """LTAA_SECRET_KEY cannot be used. Messages never quote the setting."""
