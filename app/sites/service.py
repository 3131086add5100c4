"""A site's estimates (docs/estimates.md#the-model), recomputed from its outcome rows at every read.

Per robot and feature: the prior (the configured rate of the most recent run on the site
naming the robot, created up to `as_of`), the successes and failures reported, the Beta
posterior's mean and 90% interval. Per robot and task type: planned and observed durations.
And the reliability of the plans: the success each plan expected of a task against how often
such tasks were reported done, by tenth.
"""

from __future__ import annotations

from collections.abc import Mapping
from dataclasses import dataclass, field
from datetime import datetime

from sqlalchemy.orm import Session, sessionmaker

from app.domain.errors import NotFoundError
from app.domain.estimates import (
    BetaEstimate,
    Counts,
    DurationEstimate,
    LogStats,
)
from app.store import site_repository as site_repo
from app.store.models import utcnow

# Without a configured rate for a feature (no run on the site rates it), the prior is even.
NEUTRAL_PRIOR = 0.5


class SiteNotFoundError(NotFoundError):
    def __init__(self, site: str) -> None:
        super().__init__(
            "site",
            f"no run names site '{site}'; list the sites with GET /sites (a run joins a site "
            "with `site` in POST /runs)",
        )


@dataclass(frozen=True)
class FeatureEstimate:
    feature: str
    configured: float | None  # None: no run on the site rates it (NEUTRAL_PRIOR used)
    posterior: BetaEstimate

    @property
    def shift(self) -> float:
        """Posterior mean minus the configured rate, in probability."""
        return self.posterior.mean - self.posterior.prior


@dataclass(frozen=True)
class DurationRow:
    task_type: str
    estimate: DurationEstimate
    # reason -> started/done pairs whose outcome counts but whose times taught nothing
    # (site_repo.Unmeasured; docs/estimates.md, "Durations only from times the site gave")
    left_out: Mapping[str, int] = field(default_factory=dict)


@dataclass(frozen=True)
class RobotEstimates:
    robot: str
    prior_run: str | None  # the run whose configured rates are this robot's priors
    reports: int  # tasks reported done or failed on it
    features: list[FeatureEstimate]
    durations: list[DurationRow]


@dataclass(frozen=True)
class ReliabilityBin:
    low: float
    high: float
    reports: int
    predicted: float  # mean success the plans expected
    observed: float  # share reported done


@dataclass(frozen=True)
class SiteEstimates:
    site: str
    as_of: datetime | None
    computed_at: datetime
    strength: float
    reports: int
    robots: list[RobotEstimates]
    reliability: list[ReliabilityBin]

    def largest_shifts(self, n: int = 3) -> set[tuple[str, str]]:
        """What the console marks: of the (robot, feature) pairs whose reports put the
        configured rate outside the 90% interval (the evidence contradicts it, not mere
        noise), the `n` whose learned rate moved farthest from it."""
        shifts = sorted(
            (
                (abs(f.shift), r.robot, f.feature)
                for r in self.robots
                for f in r.features
                if f.posterior.reports
                and f.configured is not None
                and not f.posterior.interval[0] <= f.configured <= f.posterior.interval[1]
            ),
            reverse=True,
        )
        return {(robot, feature) for _, robot, feature in shifts[:n]}


def site_estimates(
    *,
    sessions: sessionmaker[Session],
    site: str,
    strength: float,
    as_of: datetime | None = None,
) -> SiteEstimates:
    computed_at = utcnow()
    with sessions() as session:
        if not site_repo.site_has_runs(session=session, site=site):
            raise SiteNotFoundError(site)
        totals = site_repo.site_totals(session=session, site=site, as_of=as_of)
        seen = {robot for robot, _ in totals.outcomes}
        priors, prior_runs = site_repo.configured_priors(
            session=session, site=site, as_of=as_of, robots=seen
        )
    robots = []
    for name in sorted(set(priors) | seen):
        rates = priors.get(name, {})
        features = sorted(set(rates) | {f for r, f in totals.outcomes if r == name})
        rows = []
        for feature in features:
            counts = totals.outcomes.get((name, feature), Counts())
            configured = rates.get(feature)
            prior = NEUTRAL_PRIOR if configured is None else configured
            rows.append(
                FeatureEstimate(
                    feature,
                    configured,
                    BetaEstimate(prior, strength, counts.successes, counts.failures),
                )
            )
        durations = [
            DurationRow(
                kind,
                _duration(totals, name, kind, strength),
                dict(sorted(totals.left_out.get((name, kind), {}).items())),
            )
            for kind in sorted(
                {k for r, k in totals.durations if r == name}
                | {k for r, k in totals.planned if r == name}
                | {k for r, k in totals.left_out if r == name}
            )
        ]
        robots.append(
            RobotEstimates(
                robot=name,
                prior_run=prior_runs.get(name),
                reports=totals.robot_reports.get(name, 0),
                features=rows,
                durations=durations,
            )
        )
    return SiteEstimates(
        site=site,
        as_of=as_of,
        computed_at=computed_at,
        strength=strength,
        reports=totals.reports,
        robots=robots,
        reliability=_reliability(totals),
    )


def _duration(
    totals: site_repo.SiteTotals, robot: str, kind: str, strength: float
) -> DurationEstimate:
    planned_sum, planned_n = totals.planned.get((robot, kind), (0.0, 0))
    planned = planned_sum / planned_n if planned_n else None
    return DurationEstimate(planned, totals.durations.get((robot, kind), LogStats()), strength)


def _reliability(totals: site_repo.SiteTotals) -> list[ReliabilityBin]:
    out = []
    for index in sorted(totals.reliability):
        n, ok, mass = totals.reliability[index]
        if n:
            width = 1.0 / site_repo.BINS
            out.append(ReliabilityBin(index * width, (index + 1) * width, n, mass / n, ok / n))
    return out


def list_sites(*, sessions: sessionmaker[Session]) -> list[site_repo.SiteSummary]:
    with sessions() as session:
        return site_repo.sites(session=session)


class SiteNotFoundForImport(SiteNotFoundError):
    """`?site=` of POST /schedules/import names no site: a 404 on the query parameter."""

    location = "query"


def site_rates(
    *, sessions: sessionmaker[Session], site: str, strength: float
) -> dict[str, dict[str, float]]:
    """{robot: {feature: learned rate}}: the posterior means an imported draft's robots take
    (app.exchange.rates.fill_rates; docs/exchange.md#rates-from-a-site)."""
    try:
        e = site_estimates(sessions=sessions, site=site, strength=strength)
    except SiteNotFoundError:
        raise SiteNotFoundForImport(site) from None
    return {r.robot: {f.feature: f.posterior.mean for f in r.features} for r in e.robots}
