"""Webhook metrics, read from the tables at scrape time (as app.observability.metrics does
for runs: every replica sharing the database reports the same figures; use max())."""

from __future__ import annotations

from collections.abc import Iterator

from prometheus_client.core import (
    CounterMetricFamily,
    GaugeMetricFamily,
    HistogramMetricFamily,
    Metric,
)
from prometheus_client.registry import Collector
from sqlalchemy import case, func, select
from sqlalchemy.orm import Session, sessionmaker

from app.store.webhook_models import WebhookAttempt, WebhookDelivery
from app.webhooks.status import AttemptOutcome, DeliveryState

LATENCY_BUCKETS_S = (0.01, 0.05, 0.1, 0.25, 0.5, 1.0, 2.5, 5.0, 10.0)


def _families(
    deliveries: dict[str, int],
    attempts: dict[str, int],
    due: int,
    buckets: list[int],
    total: int,
    latency_sum_s: float,
) -> Iterator[Metric]:
    by_status = GaugeMetricFamily(
        "ltaa_webhook_deliveries", "Webhook deliveries by current status", labels=["status"]
    )
    for status in DeliveryState:
        by_status.add_metric([status.value], deliveries.get(status.value, 0))
    yield by_status
    by_outcome = CounterMetricFamily(
        "ltaa_webhook_attempts", "Webhook delivery attempts by outcome", labels=["outcome"]
    )
    for outcome in AttemptOutcome:
        by_outcome.add_metric([outcome.value], attempts.get(outcome.value, 0))
    yield by_outcome
    yield GaugeMetricFamily(
        "ltaa_webhook_queue_depth", "Pending webhook deliveries that are due now", value=due
    )
    latency = HistogramMetricFamily(
        "ltaa_webhook_delivery_latency_seconds",
        "Latency of webhook attempts that reached the receiver",
    )
    latency.add_metric(
        [],
        [(str(b), n) for b, n in zip(LATENCY_BUCKETS_S, buckets, strict=True)] + [("+Inf", total)],
        sum_value=latency_sum_s,
    )
    yield latency


class WebhookTablesCollector(Collector):
    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def describe(self) -> list[Metric]:
        return list(_families({}, {}, 0, [0] * len(LATENCY_BUCKETS_S), 0, 0.0))

    def collect(self) -> Iterator[Metric]:
        A, D = WebhookAttempt, WebhookDelivery
        with self._sessions() as session:
            deliveries = {
                s: n for s, n in session.execute(select(D.state, func.count()).group_by(D.state))
            }
            attempts = {
                o: n
                for o, n in session.execute(select(A.outcome, func.count()).group_by(A.outcome))
            }
            due = session.scalar(
                select(func.count()).where(
                    D.state == DeliveryState.PENDING,
                    D.next_attempt_at <= func.current_timestamp(),
                )
            )
            answered = A.status_code.is_not(None)
            row = session.execute(
                select(
                    *(
                        func.coalesce(
                            func.sum(case((answered & (A.latency_ms <= b * 1000), 1), else_=0)), 0
                        )
                        for b in LATENCY_BUCKETS_S
                    ),
                    func.coalesce(func.sum(case((answered, 1), else_=0)), 0),
                    func.coalesce(func.sum(case((answered, A.latency_ms), else_=0.0)), 0.0),
                )
            ).one()
        values = list(row)
        yield from _families(
            deliveries,
            attempts,
            int(due or 0),
            [int(v) for v in values[: len(LATENCY_BUCKETS_S)]],
            int(values[-2]),
            float(values[-1]) / 1000.0,
        )
