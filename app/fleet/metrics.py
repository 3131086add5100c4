"""The bridge's counters (docs/fleet.md#refused-messages), on the app's Prometheus registry."""

from __future__ import annotations

from prometheus_client import CollectorRegistry, Counter

from app.fleet.states import Refusal
from app.fleet.vda5050 import Topic


class FleetMetrics:
    def __init__(self, registry: CollectorRegistry | None = None) -> None:
        self.messages = Counter(
            "ltaa_fleet_messages",
            "VDA 5050 messages the fleet bridge received, by topic",
            ("topic",),
            registry=registry,
        )
        self.refusals = Counter(
            "ltaa_fleet_messages_refused",
            "Messages the fleet bridge refused, by reason (docs/fleet.md#refused-messages)",
            ("reason",),
            registry=registry,
        )
        self.published = Counter(
            "ltaa_fleet_messages_published",
            "Messages the fleet bridge published and the broker acknowledged, by topic",
            ("topic",),
            registry=registry,
        )

    def received(self, kind: Topic) -> None:
        self.messages.labels(kind.value).inc()

    def refused(self, why: Refusal) -> None:
        self.refusals.labels(why.value).inc()

    def sent(self, kind: str) -> None:
        self.published.labels(kind).inc()

    def refused_count(self, why: Refusal) -> float:
        return float(self.refusals.labels(why.value)._value.get())
