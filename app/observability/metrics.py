"""Prometheus metrics, each app with its own registry (several apps in one test process
never collide).

Run metrics are read from the app tables at scrape time rather than counted as they
happen: a node that LangGraph re-executes after a crash saves its decision or attempt
again (an upsert), so an in-process counter would count it twice, and it would start
from zero after a restart or on another replica. The tables hold each decision and
attempt exactly once, for every process. Every replica sharing a database therefore
reports the same totals: aggregate them with max(), not sum().
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass, field
from typing import Any

from prometheus_client import CollectorRegistry, Histogram
from prometheus_client.core import CounterMetricFamily, GaugeMetricFamily, Metric
from prometheus_client.registry import Collector
from sqlalchemy import case, func, select
from sqlalchemy.orm import Session, sessionmaker

from app.domain.lifecycle import EventKind, RunStatus
from app.domain.review import ReviewState
from app.store.models import Attempt, Decision, Review, Run, RunEvent

RUN_STATUSES = tuple(s.value for s in RunStatus)
RETRY_TIERS = ("1", "2", "3")


class Metrics:
    """The registry of one app, and the request-latency histogram the middleware feeds."""

    def __init__(self) -> None:
        self.registry = CollectorRegistry()
        self.request_seconds = Histogram(
            "ltaa_http_request_duration_seconds",
            "HTTP request latency, by method, route template and status "
            "(for /runs/{run_id}/events: how long the stream stayed open)",
            ("method", "route", "status"),
            registry=self.registry,
        )
        # Observed by the process that stores a resolution (each is stored exactly once).
        self.review_resolution_seconds = Histogram(
            "ltaa_review_resolution_seconds",
            "Time from a decision's review request to its resolution",
            buckets=(1, 5, 15, 60, 300, 900, 3600, 4 * 3600, 24 * 3600, float("inf")),
            registry=self.registry,
        )

    def review_resolved(self, waited_s: float) -> None:
        self.review_resolution_seconds.observe(max(0.0, waited_s))


@dataclass
class RunCounts:
    runs_by_status: dict[str, int] = field(default_factory=dict)
    decisions: int = 0
    fallbacks: int = 0
    llm_calls: int = 0
    input_tokens: int = 0
    output_tokens: int = 0
    transport_retries: int = 0
    hard_invalid: int = 0
    below_threshold: int = 0
    retries_by_tier: dict[str, int] = field(default_factory=dict)
    reviews_pending: int = 0
    llm_gave_up: int = 0


def _count_if(condition: Any) -> Any:
    return func.coalesce(func.sum(case((condition, 1), else_=0)), 0)


def read_counts(session: Session) -> RunCounts:
    counts = RunCounts()
    counts.runs_by_status = {
        status: n
        for status, n in session.execute(select(Run.status, func.count()).group_by(Run.status))
    }
    counts.decisions, counts.fallbacks = session.execute(
        select(func.count(), _count_if(Decision.fallback))
    ).one()
    (
        counts.llm_calls,
        counts.input_tokens,
        counts.output_tokens,
        counts.transport_retries,
        counts.hard_invalid,
        counts.below_threshold,
    ) = session.execute(
        select(
            func.count(Attempt.reply_model),  # counts non-null: attempts a model answered
            func.coalesce(func.sum(Attempt.input_tokens), 0),
            func.coalesce(func.sum(Attempt.output_tokens), 0),
            func.coalesce(func.sum(Attempt.transport_retries), 0),
            _count_if(Attempt.hard_invalid.is_not(None)),
            _count_if(Attempt.accepted.is_(False) & Attempt.hard_invalid.is_(None)),
        )
    ).one()
    counts.retries_by_tier = {
        str(tier): n
        for tier, n in session.execute(
            select(Attempt.tier, func.count()).where(Attempt.tier > 0).group_by(Attempt.tier)
        )
    }
    counts.llm_gave_up = (
        session.scalar(
            select(func.count())
            .select_from(RunEvent)
            .where(RunEvent.kind == EventKind.LLM_GAVE_UP.value)
        )
        or 0
    )
    counts.reviews_pending = (
        session.scalar(
            select(func.count())
            .select_from(Review)
            .where(Review.state == ReviewState.PENDING.value)
        )
        or 0
    )
    return counts


def families(c: RunCounts) -> Iterator[Metric]:
    runs = GaugeMetricFamily("ltaa_runs", "Runs by current status", labels=["status"])
    for status in sorted({*RUN_STATUSES, *c.runs_by_status}):
        runs.add_metric([status], c.runs_by_status.get(status, 0))
    yield runs
    yield CounterMetricFamily("ltaa_decisions", "Finalised decisions", c.decisions)
    yield CounterMetricFamily(
        "ltaa_fallbacks",
        "Decisions that fell back to the rules reasoner after every retry failed validation",
        c.fallbacks,
    )
    yield CounterMetricFamily(
        "ltaa_llm_calls",
        "Reasoner calls answered by a model (the rules reasoner makes none)",
        c.llm_calls,
    )
    yield CounterMetricFamily("ltaa_llm_input_tokens", "LLM input tokens", c.input_tokens)
    yield CounterMetricFamily("ltaa_llm_output_tokens", "LLM output tokens", c.output_tokens)
    yield CounterMetricFamily(
        "ltaa_llm_transport_retries",
        "LLM calls retried after a timeout, 429 or 5xx",
        c.transport_retries,
    )
    failures = CounterMetricFamily(
        "ltaa_validation_failures",
        "Attempts rejected by validation: hard_invalid (Q forced "
        "to 0) or below_threshold (Q under the quality threshold)",
        labels=["reason"],
    )
    failures.add_metric(["hard_invalid"], c.hard_invalid)
    failures.add_metric(["below_threshold"], c.below_threshold)
    yield failures
    retries = CounterMetricFamily(
        "ltaa_retries", "Retry attempts, by escalation tier", labels=["tier"]
    )
    for tier in sorted({*RETRY_TIERS, *c.retries_by_tier}, key=int):
        retries.add_metric([tier], c.retries_by_tier.get(tier, 0))
    yield retries
    yield CounterMetricFamily(
        "ltaa_llm_gave_up",
        "Runs that stopped asking their model after it failed too many tasks in a row "
        "(docs/reasoners.md#bounded-cost)",
        c.llm_gave_up,
    )
    yield GaugeMetricFamily(
        "ltaa_reviews_pending", "Decisions waiting for a supervisor's review", c.reviews_pending
    )


class RunTablesCollector(Collector):
    """Run metrics read from the app tables at each scrape (see the module docstring)."""

    def __init__(self, sessions: sessionmaker[Session]) -> None:
        self._sessions = sessions

    def describe(self) -> list[Metric]:
        # Names only, so registering does not query the database.
        return list(families(RunCounts()))

    def collect(self) -> Iterator[Metric]:
        with self._sessions() as session:
            counts = read_counts(session)
        yield from families(counts)
