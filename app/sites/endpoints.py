"""Learning from the site (docs/estimates.md#sites): the sites, and each site's estimates from its
reports."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Query

from app.http.deps import ClientDep, SettingsDep
from app.http.fields import SiteName
from app.http.responses import CLIENT, errors
from app.http.times import RequestTime
from app.runs.deps import RunsDep
from app.sites import service
from app.sites.schemas import (
    DurationOut,
    FeatureEstimateOut,
    ReliabilityBinOut,
    RobotEstimatesOut,
    SiteEstimatesOut,
    SiteOut,
)

router = APIRouter(prefix="/sites", tags=["sites"])


@router.get("", response_model=list[SiteOut], responses=errors(*CLIENT))
def list_sites(caller: ClientDep, runs: RunsDep) -> list[SiteOut]:
    """Every site a run names, with its runs and reports."""
    return [
        SiteOut(site=s.site, runs=s.runs, reports=s.reports, last_run_at=s.last_run_at)
        for s in service.list_sites(sessions=runs.sessions)
    ]


AsOf = Annotated[
    RequestTime | None,
    Query(
        description="Read the estimates as they stood at this time: only reports the server "
        "received by then, priors from runs created by then. RFC 3339 with an offset"
    ),
]


@router.get("/{site}/estimates", response_model=SiteEstimatesOut, responses=errors(*CLIENT, 404))
def get_estimates(
    caller: ClientDep,
    site: Annotated[SiteName, Path(description="A site, see GET /sites")],
    runs: RunsDep,
    settings: SettingsDep,
    as_of: AsOf = None,
) -> SiteEstimatesOut:
    """Per robot and feature: prior, successes, failures, posterior mean and 90% interval;
    per robot and task type: planned and observed durations; and the plans' reliability.
    Recomputed from the execution reports at every call."""
    return estimates_out(
        service.site_estimates(
            sessions=runs.sessions, site=site, strength=settings.prior_strength, as_of=as_of
        )
    )


def estimates_out(e: service.SiteEstimates) -> SiteEstimatesOut:
    marked = e.largest_shifts()
    return SiteEstimatesOut(
        site=e.site,
        as_of=e.as_of,
        computed_at=e.computed_at,
        prior_strength=e.strength,
        reports=e.reports,
        robots=[
            RobotEstimatesOut(
                robot=r.robot,
                prior_from_run=r.prior_run,
                reports=r.reports,
                features=[
                    FeatureEstimateOut(
                        feature=f.feature,
                        prior=f.posterior.prior,
                        configured=f.configured is not None,
                        prior_strength=f.posterior.strength,
                        successes=f.posterior.successes,
                        failures=f.posterior.failures,
                        posterior_mean=f.posterior.mean,
                        interval=f.posterior.interval,
                        shift=f.shift,
                        marked=(r.robot, f.feature) in marked,
                    )
                    for f in r.features
                ],
                durations=[
                    DurationOut(
                        task_type=d.task_type,
                        planned_minutes=d.estimate.planned,
                        observed=d.estimate.observed.n,
                        left_out=dict(d.left_out),
                        observed_median_minutes=d.estimate.observed_median,
                        estimate_minutes=d.estimate.median,
                        interval=d.estimate.interval,
                    )
                    for d in r.durations
                ],
            )
            for r in e.robots
        ],
        reliability=[
            ReliabilityBinOut(
                low=b.low,
                high=b.high,
                reports=b.reports,
                predicted=b.predicted,
                observed=b.observed,
            )
            for b in e.reliability
        ],
    )
