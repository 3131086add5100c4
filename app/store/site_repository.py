"""Keyword-only data access for the site estimates (docs/estimates.md#counting-each-report-once):
the outcome rows written with each report, the aggregates the estimates are computed from, and the
configured rates that serve as priors.

One derivation turns a reported task into its rows (`outcome_rows`), used both when a report
arrives and when the table is rebuilt from the record, so the two cannot drift apart.
"""

from __future__ import annotations

import hashlib
import json
import math
from collections.abc import Iterable, Mapping, Sequence
from dataclasses import dataclass, field
from datetime import UTC, datetime
from enum import StrEnum
from typing import Any

from sqlalchemy import Select, delete, func, select
from sqlalchemy.orm import Session

from app.domain.estimates import Counts, LogStats, SiteCounts, configured_rates
from app.store.models import Decision, Run, as_utc
from app.store.site_models import SiteReport

FINAL_STATES = ("done", "failed")
BINS = 10


class Unmeasured(StrEnum):
    """Why a started -> done (or failed) pair teaches no duration (docs/estimates.md,
    "Durations only from times the site gave"); its outcome still counts."""

    # Both in one request, not both with `at`: the times are the server's clock reading
    # the request twice, microseconds apart, not the site's.
    TOGETHER_WITHOUT_AT = "together_without_at"
    ZERO_LENGTH = "zero_length"  # the site gave the same time to both


@dataclass(frozen=True)
class Reported:
    """A task reported done or failed on a run: what its outcome row is made of."""

    task_index: int
    task_id: str
    state: str
    at: datetime  # when the site says it ended
    started_at: datetime | None
    # Its `started` came in the same request, and not both carried `at`.
    together_without_at: bool = False


# How an execution-report record marks an update sent without `at`: its time is the
# server's clock, which the rule below needs to know when the rows are rebuilt.
SERVER_CLOCK = {"clock": "server"}


def together_without_at(started_here: Mapping[str, bool], task_id: str, *, at_sent: bool) -> bool:
    """Whether a final update teaches no duration because its `started` came in the same
    request and not both carry `at` (docs/estimates.md, "Durations only from times the
    site gave"). `started_here`: task id -> whether its `started` in that request had `at`."""
    if task_id not in started_here:
        return False  # started in an earlier request (or never): two receipts, two times
    return not (started_here[task_id] and at_sent)


def _task_facts(request: Mapping[str, Any], task_index: int) -> Mapping[str, Any]:
    tasks = request["instance_data"]["tasks"]
    return tasks[task_index] if 0 <= task_index < len(tasks) else {}


def planned_minutes(task: Mapping[str, Any], robot: str) -> float | None:
    """The task's configured duration on this robot (docs/schedules.md#the-model: minutes, or
    minutes by robot); None for an untimed task."""
    duration = task.get("duration")
    if isinstance(duration, Mapping):
        duration = duration.get(robot)
    if isinstance(duration, int | float) and not isinstance(duration, bool) and duration > 0:
        return float(duration)
    return None


def outcome_row(
    *,
    run: Run,
    reported: Reported,
    decision: Decision,
    received_at: datetime,
    member: tuple[str, str] | None = None,
) -> dict[str, Any]:
    """The row of a reported task on its robot; `member` (robot, feature): the row of one member
    of a team task, which counts on the feature that member covered
    (docs/estimates.md#teams-count-once-per-member)."""
    task = _task_facts(run.request, reported.task_index)
    robot = decision.robot_name if member is None else member[0]
    ended, started = as_utc(reported.at), reported.started_at
    minutes, unmeasured = None, None
    if started is not None and reported.together_without_at:
        unmeasured = Unmeasured.TOGETHER_WITHOUT_AT.value
    elif started is not None:
        span = (ended - as_utc(started)).total_seconds() / 60.0
        minutes = span if span > 0 else None  # a zero-length task says nothing of duration
        unmeasured = None if span > 0 else Unmeasured.ZERO_LENGTH.value
    predicted = float(decision.expected_success)
    covered = task.get("features", []) if member is None else [member[1]]
    features = json.dumps(sorted(covered))
    return {
        "site": run.site,
        "run_id": run.id,
        "task_index": reported.task_index,
        "task_id": reported.task_id,
        "robot": robot,
        "task_type": str(task.get("type") or "Custom"),
        "features": features,
        "feature_set": hashlib.sha256(features.encode()).hexdigest(),
        "success": reported.state == "done",
        "predicted": predicted,
        "predicted_bin": min(BINS - 1, max(0, int(predicted * BINS))),
        "reported_at": ended,
        "received_at": as_utc(received_at),
        "minutes": minutes,
        "log_minutes": None if minutes is None else math.log(minutes),
        "planned_minutes": planned_minutes(task, robot),
        "unmeasured": unmeasured,
    }


def outcome_rows(
    *, run: Run, reported: Reported, decision: Decision, received_at: datetime
) -> list[dict[str, Any]]:
    """A reported task's rows: one, or for a team task one per member, each on the feature it
    covered, with the same outcome and times (docs/estimates.md#teams-count-once-per-member)."""
    members: list[tuple[str, str] | None] = (
        [(str(m["robot"]), str(m["feature"])) for m in decision.team] if decision.team else [None]
    )
    return [
        outcome_row(
            run=run, reported=reported, decision=decision, received_at=received_at, member=m
        )
        for m in members
    ]


def _decisions(session: Session, run_id: str, indexes: Iterable[int]) -> dict[int, Decision]:
    wanted = sorted(set(indexes))
    if not wanted:
        return {}
    rows = session.scalars(
        select(Decision).where(Decision.run_id == run_id, Decision.task_index.in_(wanted))
    )
    return {d.task_index: d for d in rows}


def record_outcomes(
    *, session: Session, run: Run, reported: Sequence[Reported], received_at: datetime
) -> int:
    """Write the outcome rows of the tasks just reported done or failed, in the report's
    transaction; returns how many."""
    final = [r for r in reported if r.state in FINAL_STATES]
    decided = _decisions(session, run.id, (r.task_index for r in final))
    rows = [
        row
        for r in final
        if r.task_index in decided
        for row in outcome_rows(
            run=run, reported=r, decision=decided[r.task_index], received_at=received_at
        )
    ]
    for values in rows:
        session.add(SiteReport(**values))
    return len(rows)


# -- reading ----------------------------------------------------------------------------


@dataclass
class SiteTotals:
    """Everything the estimates of one site need, from one pass over its rows."""

    outcomes: dict[tuple[str, str], Counts] = field(default_factory=dict)  # (robot, feature)
    durations: dict[tuple[str, str], LogStats] = field(default_factory=dict)  # (robot, type)
    planned: dict[tuple[str, str], tuple[float, int]] = field(default_factory=dict)  # sum, n
    # (robot, type) -> reason -> started/done pairs that taught no duration
    left_out: dict[tuple[str, str], dict[str, int]] = field(default_factory=dict)
    reliability: dict[int, tuple[int, int, float]] = field(default_factory=dict)  # bin: n, ok, Σp
    robot_reports: dict[str, int] = field(default_factory=dict)
    reports: int = 0


def _until(query: Select[Any], as_of: datetime | None) -> Select[Any]:
    return query if as_of is None else query.where(SiteReport.received_at <= as_utc(as_of))


_GROUP = (
    SiteReport.robot,
    SiteReport.feature_set,
    SiteReport.task_type,
    SiteReport.predicted_bin,
    SiteReport.success,
    SiteReport.unmeasured,
)


def site_totals(*, session: Session, site: str, as_of: datetime | None = None) -> SiteTotals:
    """One grouped scan of the site's rows received up to `as_of` (None: all)."""
    query: Any = select(
        *_GROUP,
        func.count(),
        func.count(SiteReport.log_minutes),
        func.sum(SiteReport.log_minutes),
        func.sum(SiteReport.log_minutes * SiteReport.log_minutes),
        func.sum(SiteReport.planned_minutes),
        func.count(SiteReport.planned_minutes),
        func.sum(SiteReport.predicted),
        func.min(SiteReport.id),  # a row naming the feature set (SQLite: the index has it)
    ).where(SiteReport.site == site)
    query = _until(query, as_of).group_by(*_GROUP)
    totals = SiteTotals()
    groups = list(session.execute(query))
    example = {row[-1] for row in groups}
    named = (
        dict(
            session.execute(
                select(SiteReport.feature_set, SiteReport.features).where(
                    SiteReport.id.in_(example)
                )
            ).all()
        )
        if example
        else {}
    )
    row: Any
    for row in groups:
        robot, feature_set, task_type, bin_, ok, why, n, n_dur, s1, s2, planned, n_planned, p, _ = (
            row
        )
        features = named[feature_set]
        totals.reports += n
        totals.robot_reports[robot] = totals.robot_reports.get(robot, 0) + n
        one: Counts = Counts(n, 0) if ok else Counts(0, n)
        for feature in json.loads(features):
            key = (robot, feature)
            totals.outcomes[key] = totals.outcomes.get(key, Counts()) + one
        kind = (robot, task_type)
        if why is not None:
            reasons = totals.left_out.setdefault(kind, {})
            reasons[why] = reasons.get(why, 0) + n
        if n_dur:
            totals.durations[kind] = totals.durations.get(kind, LogStats()) + LogStats(
                n_dur, float(s1 or 0.0), float(s2 or 0.0)
            )
        if n_planned:
            total, count = totals.planned.get(kind, (0.0, 0))
            totals.planned[kind] = (total + float(planned), count + n_planned)
        seen, good, mass = totals.reliability.get(bin_, (0, 0, 0.0))
        totals.reliability[bin_] = (seen + n, good + (n if ok else 0), mass + float(p or 0.0))
    return totals


def site_counts(*, session: Session, site: str) -> SiteCounts:
    """What a run asking for learned rates or durations plans with: every report of the
    site so far."""
    totals = site_totals(session=session, site=site)
    return SiteCounts(totals.outcomes, totals.durations, totals.reports)


@dataclass(frozen=True)
class SiteSummary:
    site: str
    runs: int
    reports: int
    last_run_at: datetime | None


def sites(*, session: Session) -> list[SiteSummary]:
    runs = session.execute(
        select(Run.site, func.count(), func.max(Run.created_at)).group_by(Run.site)
    ).all()
    reports = dict(
        session.execute(select(SiteReport.site, func.count()).group_by(SiteReport.site)).all()
    )
    return sorted(
        (SiteSummary(s, n, int(reports.get(s, 0)), last) for s, n, last in runs),
        key=lambda x: x.site,
    )


def site_has_runs(*, session: Session, site: str, as_of: datetime | None = None) -> bool:
    query = select(Run.id).where(Run.site == site)
    if as_of is not None:
        query = query.where(Run.created_at <= as_utc(as_of))
    return session.execute(query.limit(1)).first() is not None


def configured_priors(
    *, session: Session, site: str, as_of: datetime | None, robots: Iterable[str] = ()
) -> tuple[dict[str, dict[str, float]], dict[str, str]]:
    """The prior of each robot: the configured rates of the most recent run on the site
    (created up to `as_of`) that names it, for every robot of the newest run and those in
    `robots`. Returns (robot -> feature -> rate, robot -> the run id it comes from). Runs
    are read newest first and only until every robot asked for is found."""
    query = select(Run.id).where(Run.site == site).order_by(Run.created_at.desc(), Run.id)
    if as_of is not None:
        query = query.where(Run.created_at <= as_utc(as_of))
    wanted = set(robots)
    priors: dict[str, dict[str, float]] = {}
    source: dict[str, str] = {}
    first = True
    for (run_id,) in session.execute(query):
        run = session.get(Run, run_id)
        assert run is not None
        request = run.request
        fleet = configured_rates(request["instance_data"]["robots"], request.get("learned"))
        for robot in fleet:
            name = str(robot["name"])
            if first:
                wanted.add(name)
            if name in wanted and name not in priors:
                priors[name] = {f: float(v) for f, v in robot["success"].items()}
                source[name] = run.id
        first = False
        session.expunge(run)  # a long walk must not keep every request in memory
        if wanted <= set(priors):
            break
    return priors, source


# -- rebuilding ---------------------------------------------------------------------------


def replace_all(*, session: Session, rows: Iterable[Mapping[str, Any]]) -> int:
    """Empty the table and write these rows (app.sites.rebuild), in the caller's
    transaction; on PostgreSQL the table is locked first, so a report arriving meanwhile
    waits and then adds its row to the rebuilt table rather than to the old one."""
    if session.get_bind().dialect.name == "postgresql":
        session.connection().exec_driver_sql("LOCK TABLE site_reports IN EXCLUSIVE MODE")
    session.execute(delete(SiteReport))
    count = 0
    for values in rows:
        session.add(SiteReport(**values))
        count += 1
    return count


def stored_rows(*, session: Session) -> list[dict[str, Any]]:
    """Every outcome row as plain values (without the surrogate id), for comparisons."""
    columns = [c for c in SiteReport.__table__.columns if c.name != "id"]
    out = []
    order = (SiteReport.run_id, SiteReport.task_index, SiteReport.robot)
    for row in session.execute(select(*columns).order_by(*order)):
        values = dict(row._mapping)
        for key in ("reported_at", "received_at"):
            values[key] = as_utc(values[key]).astimezone(UTC)
        out.append(values)
    return out
