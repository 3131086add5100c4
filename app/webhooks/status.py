"""Delivery and attempt states."""

from __future__ import annotations

from enum import StrEnum


class DeliveryState(StrEnum):
    PENDING = "pending"  # due at next_attempt_at (claimed while an attempt is in flight)
    DELIVERED = "delivered"  # a 2xx answered
    FAILED = "failed"  # every scheduled attempt failed (or a manual retry did)
    CANCELLED = "cancelled"  # its subscription was deleted before it was delivered


class AttemptOutcome(StrEnum):
    DELIVERED = "delivered"
    HTTP_ERROR = "http_error"  # the receiver answered, but not 2xx (3xx included)
    NETWORK_ERROR = "network_error"  # no answer: refused, reset, timeout, TLS
    REFUSED = "refused"  # not sent: the target is not allowed (SSRF) or unresolvable
    SECRET_ERROR = "secret_error"  # not sent: the secret could not be decrypted
