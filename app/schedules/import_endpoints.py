"""POST /schedules/import (client): a site's MS Project (MSPDI) or Primavera P6 (XER) file
to a draft instance (docs/exchange.md), read by app.exchange through app.schedules.service.

The HTTP side of the schedule files, here and not in app.exchange: the readers sit low,
beside app.schedule_views, and import only the domain (a contract), so they can take
neither the client-role dependency and the error responses (app.http) nor a site's
learned rates (app.sites). This package sits above both, so the router carries its
access check and responses, and `?site=` is read by app.schedules.service, which the
console's import page calls too. Nothing is stored: the caller edits the draft (rates, say)
and posts it. The body's size limit is LTAA_IMPORT_MAX_BYTES (413 above it, enforced while
reading by the body-size middleware, to which app.main hands app.api.routers.body_limits).
"""

from __future__ import annotations

from typing import Annotated, Literal

from fastapi import APIRouter, Depends, Header, Query, Request
from fastapi.concurrency import run_in_threadpool

from app.http.deps import SettingsDep, require_client
from app.http.responses import CLIENT, ErrorOut, errors
from app.runs.deps import RunsDep
from app.schedules import service
from app.schedules.schemas import ImportedDraft

IMPORT_PATH = "/schedules/import"

_UNKNOWN_SITE = {"model": ErrorOut, "description": "No run names the site of ?site="}
router = APIRouter(
    tags=["schedules"],
    dependencies=[Depends(require_client)],
    responses={**errors(*CLIENT, 413), 404: _UNKNOWN_SITE},
)


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
    runs: RunsDep,
    settings: SettingsDep,
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
        lambda: service.import_draft(
            data,
            sessions=runs.sessions,
            prior_strength=settings.prior_strength,
            format=format_,
            content_type=content_type,
            features_field=features_field,
            default_features=default_features,
            site=site,
        )
    )
    return ImportedDraft.model_validate(draft.to_dict())
