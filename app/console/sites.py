"""GET /console/sites and /console/sites/{site} (docs/estimates.md#the-site-page): the sites, and a
site's learned rates with their intervals and report counts, the ones farthest from the configured
rates marked, observed durations and the plans' reliability."""

from __future__ import annotations

from typing import Annotated

from fastapi import APIRouter, Path, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import Response

from app.console.context import ConsoleDep, PageNotFound, SignedInDep, finish, sessions_of
from app.console.site_charts import Bin, RateRow, rates_chart, reliability_chart
from app.domain.models import MAX_NAME_CHARS
from app.sites import service

router = APIRouter(prefix="/console", include_in_schema=False)

# Why a started/done pair taught no duration, as the durations table says it.
LEFT_OUT_REASONS = {
    "together_without_at": "sent in one request without both times (at)",
    "zero_length": "started and ended at the same time",
}


@router.get("/sites")
async def sites_page(request: Request, console: ConsoleDep, signed: SignedInDep) -> Response:
    found = await run_in_threadpool(service.list_sites, sessions=sessions_of(request))
    context = {"title": "Sites", "sites": found}
    return finish(request, console.render(request, "sites.html", context, signed=signed))


@router.get("/sites/{site}")
async def site_page(
    request: Request,
    site: Annotated[str, Path(min_length=1, max_length=MAX_NAME_CHARS, pattern=r"^[^\x00]+$")],
    console: ConsoleDep,
    signed: SignedInDep,
) -> Response:
    try:
        e = await run_in_threadpool(
            service.site_estimates,
            sessions=sessions_of(request),
            site=site,
            strength=console.settings.prior_strength,
        )
    except service.SiteNotFoundError as exc:
        raise PageNotFound(exc.message) from None
    marked = e.largest_shifts()
    rows = [
        RateRow(
            label=f"{r.robot} · {f.feature}",
            configured=f.posterior.prior,
            mean=f.posterior.mean,
            low=f.posterior.interval[0],
            high=f.posterior.interval[1],
            reports=f.posterior.reports,
            marked=(r.robot, f.feature) in marked,
        )
        for r in e.robots
        for f in r.features
    ]
    bins = [Bin(b.predicted, b.observed, b.reports) for b in e.reliability]
    context = {
        "title": f"Site {site}",
        "e": e,
        "marked": marked,
        "rates_chart": rates_chart(rows) if rows else None,
        "reliability_chart": reliability_chart(bins),
        "left_out_reasons": LEFT_OUT_REASONS,
    }
    return finish(request, console.render(request, "site.html", context, signed=signed))
