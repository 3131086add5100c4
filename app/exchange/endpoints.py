"""POST /schedules/import (client): a site's MS Project (MSPDI) or Primavera P6 (XER) file
to a draft instance, and the MSPDI answer of GET /runs/{id}/schedule?format=mspdi.

The HTTP side of app.exchange. It imports nothing of the HTTP kit (app.exchange sits below
it, beside app.schedule_views, and imports only the domain): app.api.routers mounts the router
with the client-role dependency and the error responses. Nothing is stored: the caller
edits the draft (rates, say) and posts it. The body's size limit is LTAA_IMPORT_MAX_BYTES
(413 above it, enforced while reading by the body-size middleware, to which app.main hands
app.api.routers.body_limits).
"""

from __future__ import annotations

from collections.abc import Callable, Mapping
from typing import Annotated, Any, Literal

from fastapi import APIRouter, Header, Query, Request
from fastapi.concurrency import run_in_threadpool
from pydantic import BaseModel, Field

from app.exchange.rates import fill_rates
from app.exchange.read import read_schedule

IMPORT_PATH = "/schedules/import"

# site -> {robot: {feature: learned rate}}, raising a 404 error for an unknown site. Handed
# in by app.api.routers as `app.state.site_rates` (the site's estimates live in app.sites, a layer
# this package must not import).
SiteRates = Callable[[str], Mapping[str, Mapping[str, float]]]

router = APIRouter(tags=["schedules"])


class ImportedDraft(BaseModel):
    """A draft instance: `tasks`, `robots`, `start` as a request sends them, plus what was
    read and what was not (docs/exchange.md)."""

    tasks: list[dict[str, Any]] = Field(description="Tasks in the shape a request sends")
    robots: list[dict[str, Any]] = Field(description="The assigned resources, rates empty")
    start: str | None = Field(description="The project's start (RFC 3339)")
    source: dict[str, Any] = Field(
        description="format, project, calendar, features_field, counts read and imported, "
        "and the calendar caveat"
    )
    skipped: list[dict[str, Any]] = Field(description="Each item not imported, with why")


_BODY = {
    "requestBody": {
        "required": True,
        "content": {
            "application/xml": {"schema": {"type": "string", "format": "binary"}},
            "application/octet-stream": {"schema": {"type": "string", "format": "binary"}},
        },
        "description": "The file: MS Project XML (MSPDI) or a Primavera P6 XER export",
    }
}


@router.post(IMPORT_PATH, response_model=ImportedDraft, openapi_extra=_BODY)
async def import_schedule(
    request: Request,
    format_: Annotated[
        Literal["mspdi", "xer"] | None,
        Query(alias="format", description="mspdi or xer; default: told by the first bytes"),
    ] = None,
    features_field: Annotated[
        str | None,
        Query(
            max_length=200,
            description="The field holding each task's features, comma-separated: an MS "
            "Project text field (Text1) or its alias, a P6 user field or activity code; "
            "default: the field called Features, else Text1",
        ),
    ] = None,
    default_features: Annotated[
        str | None,
        Query(
            max_length=2000,
            description="Comma-separated features for tasks without any (else skipped)",
        ),
    ] = None,
    site: Annotated[
        str | None,
        Query(
            min_length=1,
            max_length=200,
            pattern=r"^[^\x00]+$",
            description="Fill the robots' rates from this site's learned estimates (GET "
            "/sites/{site}/estimates); an unknown site is a 404",
        ),
    ] = None,
    content_type: Annotated[str | None, Header()] = None,
) -> ImportedDraft:
    """A schedule file as a draft instance: nothing is stored (docs/exchange.md)."""
    data = await request.body()
    draft = await run_in_threadpool(
        lambda: read_schedule(
            data,
            format=format_,
            content_type=content_type,
            features_field=features_field,
            default_features=default_features,
        )
    )
    if site is not None:
        site_rates: SiteRates = request.app.state.site_rates
        rates = await run_in_threadpool(site_rates, site)
        draft = fill_rates(draft, rates, site=site)
    return ImportedDraft.model_validate(draft.to_dict())
