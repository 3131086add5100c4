"""GET/POST /console/import and POST /console/import/run (docs/exchange.md#the-console-page):
a site's MS Project or P6 file uploaded, its draft shown (tasks, links, robots and their
rates, what was skipped and why, the source), and the draft started as a run.

Over app.schedules.service (the file read by app.exchange, a site's learned rates from
app.sites: what POST /schedules/import calls), app.sites (the sites to choose from) and
app.runs (the run service POST /runs calls), like the other pages. The draft is started
as the file has it, typed links and lags included (docs/schedules.md#links).
"""

from __future__ import annotations

import json
from typing import Annotated, Any

from fastapi import APIRouter, Form, Request, UploadFile
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import RedirectResponse, Response

from app.console.context import ConsoleDep, CsrfDep, SignedInDep, finish, sessions_of
from app.domain.errors import DomainError
from app.domain.estimates import DEFAULT_SITE
from app.domain.models import MAX_NAME_CHARS
from app.domain.serialize import instance_from_dict
from app.exchange import Draft, ExchangeError
from app.runs import service as run_service
from app.runs.spec import RunOrder
from app.schedules import service as import_service
from app.sites import service as site_service

CONSOLE_IMPORT_PATH = "/console/import"
router = APIRouter(prefix="/console", include_in_schema=False)
# A started draft comes back as the hidden form field the page wrote: a run request's size.
MAX_DRAFT_CHARS = 10 * 1024 * 1024


def _sites(request: Request) -> list[str]:
    return [s.site for s in site_service.list_sites(sessions=sessions_of(request))]


@router.get("/import")
async def import_page(request: Request, console: ConsoleDep, signed: SignedInDep) -> Response:
    sites = await run_in_threadpool(_sites, request)
    context = {"title": "Import a schedule", "sites": sites, "form": {}}
    return finish(request, console.render(request, "import.html", context, signed=signed))


def _unrated(draft: Draft) -> list[str]:
    """The features of the draft's tasks that no robot has a rate for: a run would refuse
    them."""
    rated = {f for r in draft.robots for f in r["success"]}
    return sorted({f for t in draft.tasks for f in t["features"]} - rated)


@router.post("/import")
async def import_file(
    request: Request,
    console: ConsoleDep,
    signed: CsrfDep,
    file: UploadFile,
    format_: Annotated[str, Form(alias="format", max_length=10)] = "",
    features_field: Annotated[str, Form(max_length=200)] = "",
    default_features: Annotated[str, Form(max_length=2000)] = "",
    site: Annotated[str, Form(max_length=MAX_NAME_CHARS)] = "",
) -> Response:
    """The uploaded file's draft, shown: nothing is stored until "Start a run"."""
    form = {
        "format": format_ if format_ in ("mspdi", "xer") else "",
        "features_field": features_field.strip(),
        "default_features": default_features.strip(),
        "site": site.strip(),
    }

    def refuse(message: str, status_code: int) -> Response:
        return console.refused(
            request,
            title="Not imported",
            message=message,
            retry=CONSOLE_IMPORT_PATH,
            signed=signed,
            status_code=status_code,
        )

    limit = console.settings.import_max_bytes
    data = await file.read(limit + 1)
    if len(data) > limit:
        return refuse(
            f"The file is larger than {limit:,} bytes (LTAA_IMPORT_MAX_BYTES): raise the "
            "limit for a file that size.",
            413,
        )

    kind = form["format"]
    try:
        draft = await run_in_threadpool(
            lambda: import_service.import_draft(
                data,
                sessions=sessions_of(request),
                prior_strength=console.settings.prior_strength,
                format="mspdi" if kind == "mspdi" else "xer" if kind == "xer" else None,
                features_field=form["features_field"] or None,
                default_features=form["default_features"] or None,
                site=form["site"] or None,
            )
        )
        sites = await run_in_threadpool(_sites, request)
    except ExchangeError as exc:
        where = f"{exc.field}: " if exc.field and exc.field != "links" else ""
        return refuse(f"{file.filename or 'The file'} was not imported: {where}{exc.message}.", 422)
    except site_service.SiteNotFoundError as exc:
        return refuse(f"Site '{form['site']}': {exc.message}.", 404)
    context = _draft_context(draft, form, file.filename or "", sites)
    return finish(request, console.render(request, "import.html", context, signed=signed))


def _draft_context(
    draft: Draft, form: dict[str, str], filename: str, sites: list[str]
) -> dict[str, Any]:
    unrated = _unrated(draft)
    startable = not unrated
    return {
        "title": "Import a schedule",
        "sites": sites,
        "form": form,
        "filename": filename,
        "draft": draft,
        "unrated": unrated,
        "startable": startable,
        "request_json": json.dumps(draft.request()) if startable else "",
    }


def _order(request_json: str, site: str) -> RunOrder:
    try:
        instance = instance_from_dict(json.loads(request_json))
    except DomainError:
        raise  # the instance's own checks: the field and the problem
    except (ValueError, KeyError, TypeError, AttributeError):
        raise DomainError("draft", "it is not a run request; import the file again") from None
    sent = {"tasks", "robots"} | ({"start"} if instance.start is not None else set())
    return RunOrder(
        tasks=instance.tasks,
        robots=instance.robots,
        start=instance.start,
        site=site or DEFAULT_SITE,
        sent=frozenset(sent | ({"site"} if site else set())),
    )


@router.post("/import/run")
async def start_run(
    request: Request,
    console: ConsoleDep,
    signed: CsrfDep,
    draft: Annotated[str, Form(max_length=MAX_DRAFT_CHARS)],
    site: Annotated[str, Form(max_length=MAX_NAME_CHARS)] = "",
) -> Response:
    """The draft as POST /runs takes it, started; then its run page."""

    def submit() -> str:
        order = _order(draft, site.strip())
        run, _ = run_service.submit_run(
            sessions=sessions_of(request),
            worker=request.app.state.runs.worker,
            settings=console.settings,
            order=order,
            idempotency=None,
        )
        return run.id

    try:
        run_id = await run_in_threadpool(submit)
    except DomainError as exc:
        return console.refused(
            request,
            title="Run not started",
            message=f"The draft was not started: {exc.field}: {exc.message}.",
            retry=CONSOLE_IMPORT_PATH,
            signed=signed,
            status_code=exc.status_code if 400 <= exc.status_code < 500 else 422,
        )
    return RedirectResponse(f"/console/runs/{run_id}", status_code=303)
