"""The console's pages: runs, a run, its attempts' prompts, its chain check and export,
the reviews queue; and the run actions a supervisor may take from a run page."""

from __future__ import annotations

from collections.abc import Callable
from typing import Annotated, Any, TypeVar

from fastapi import APIRouter, Form, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import RedirectResponse, Response

from app.audit.verify import verify_trace
from app.console import browse, views
from app.console.context import (
    ConsoleDep,
    CsrfDep,
    PageNotFound,
    RunIdDep,
    SignedInDep,
    finish,
    no_run,
    sessions_of,
)
from app.domain.errors import DomainError, RunNotFoundError, RunStateConflictError
from app.domain.lifecycle import ACTIVE, FINISHED, RunStatus
from app.plans.revisions import RevisionConflictError
from app.reviews import signoff
from app.reviews.schemas import MAX_STATEMENT_CHARS
from app.runs import service
from app.runs import views as run_views
from app.runs.trace import jsonl_trace

router = APIRouter(prefix="/console", include_in_schema=False)
RUNS_PER_PAGE = 50
T = TypeVar("T")


async def _in_run(request: Request, run_id: str, read: Callable[..., T], /, **kwargs: Any) -> T:
    """The shell of every run page and action: `read(**kwargs)` off the event loop (it
    reads or writes the store), and a run that is not there is the console's own 404 page."""
    try:
        return await run_in_threadpool(read, **kwargs)
    except RunNotFoundError:
        raise no_run(request, run_id) from None


def _status_filter(raw: str | None) -> RunStatus | None:
    try:
        return RunStatus(raw) if raw else None
    except ValueError:
        return None


def _runs_context(request: Request, status: str | None, page: int) -> dict[str, object]:
    chosen = _status_filter(status)
    page = max(1, page)
    rows = run_views.list_run_rows(
        sessions=sessions_of(request),
        status=chosen,
        limit=RUNS_PER_PAGE + 1,  # one more: is there an older page?
        offset=(page - 1) * RUNS_PER_PAGE,
    )
    return {
        "runs": rows[:RUNS_PER_PAGE],
        "more": len(rows) > RUNS_PER_PAGE,
        "page": page,
        "status": chosen,
        "statuses": list(RunStatus),
        "active": {s.value for s in ACTIVE},
    }


@router.get("")
async def runs_page(
    request: Request,
    console: ConsoleDep,
    signed: SignedInDep,
    status: Annotated[str | None, Query(max_length=32)] = None,
    page: Annotated[int, Query(ge=1, le=1_000_000)] = 1,
) -> Response:
    context = await run_in_threadpool(_runs_context, request, status, page)
    return finish(
        request,
        console.render(request, "runs.html", {"title": "Runs", **context}, signed=signed),
    )


@router.get("/runs-table")
async def runs_table(
    request: Request,
    console: ConsoleDep,
    signed: SignedInDep,
    status: Annotated[str | None, Query(max_length=32)] = None,
    page: Annotated[int, Query(ge=1, le=1_000_000)] = 1,
) -> Response:
    """The runs table's rows alone: what the list page re-reads while a run is active."""
    context = await run_in_threadpool(_runs_context, request, status, page)
    return console.render(request, "runs_rows.html", context, signed=signed)


@router.get("/runs/{run_id}")
async def run_page(
    request: Request,
    run_id: RunIdDep,
    console: ConsoleDep,
    signed: SignedInDep,
    page: Annotated[int, Query(ge=1, le=1_000_000)] = 1,
    decision: Annotated[int | None, Query(ge=0, le=1_000_000)] = None,
) -> Response:
    view = await _in_run(
        request,
        run_id,
        views.run_page,
        sessions=sessions_of(request),
        run_id=run_id,
        page_number=page,
        open_decision=decision,
        cache_dir=console.settings.data_dir / "console-cache",
    )
    run = view.overview.run
    model = view.model or (console.settings.default_model if run.reasoner == "anthropic" else None)
    context = {
        "title": f"Run {run.id[:8]}",
        "v": view,
        "run": run,
        "model": model,
        # The page follows any run that may still change (awaiting review, interrupted...).
        "finished": run.status in {s.value for s in FINISHED},
        "can_cancel": run.status in {s.value for s in ACTIVE},
        "can_resume": run.status in (RunStatus.INTERRUPTED, RunStatus.FAILED),
        "inline_tasks": views.INLINE_TASKS,
        "scores_of": views.scores_of,
        "final_attempt": views.final_attempt,
        "team_lines": views.team_lines,
    }
    return finish(request, console.render(request, "run.html", context, signed=signed))


async def _part(
    request: Request,
    console: ConsoleDep,
    signed: SignedInDep,
    *,
    run_id: str,
    template: str,
    fragment: bool,
    fetch: Callable[[], dict[str, Any]],
) -> Response:
    """A part of a run page read on demand: drawn into the page (fragment=1), or a page of
    its own for a browser without script."""
    try:
        context = await _in_run(request, run_id, fetch)
    except (browse.AttemptNotFoundError, RevisionConflictError) as exc:
        raise PageNotFound(exc.message if isinstance(exc, DomainError) else str(exc)) from None
    # Without script, the part is a page of its own (part.html) around the same fragment.
    page = {"back": f"/console/runs/{run_id}", "back_text": "Back to the run", "heading": ""}
    context = {"run_id": run_id, **page, **context, "fragment": f"{template}_fragment.html"}
    name = context["fragment"] if fragment else "part.html"
    return finish(request, console.render(request, name, context, signed=signed))


@router.get("/runs/{run_id}/attempts/{task_index}/{attempt}")
async def attempt_page(
    request: Request,
    run_id: RunIdDep,
    task_index: int,
    attempt: int,
    console: ConsoleDep,
    signed: SignedInDep,
    fragment: bool = False,
) -> Response:
    """One attempt's prompts and reply."""

    def fetch() -> dict[str, Any]:
        row = browse.attempt_detail(
            sessions=sessions_of(request), run_id=run_id, task_index=task_index, attempt=attempt
        )
        title = f"Task {task_index}, attempt {attempt}"
        back = f"/console/runs/{run_id}?decision={task_index}#decision-{task_index}"
        return {
            "title": title,
            "heading": title,
            "back": back,
            "back_text": "Back to the decision",
            "a": row,
        }

    return await _part(
        request, console, signed, run_id=run_id, template="attempt", fragment=fragment, fetch=fetch
    )


@router.get("/runs/{run_id}/frontier")
async def frontier_page(
    request: Request,
    run_id: RunIdDep,
    console: ConsoleDep,
    signed: SignedInDep,
    fragment: bool = False,
) -> Response:
    """The run on the exact frontier: computed (and cached) here on a large run's first visit."""

    def fetch() -> dict[str, Any]:
        part = views.run_frontier(
            sessions=sessions_of(request),
            run_id=run_id,
            cache_dir=console.settings.data_dir / "console-cache",
        )
        return {"title": "Frontier", "heading": f"Run {run_id} on the frontier", "f": part}

    return await _part(
        request, console, signed, run_id=run_id, template="frontier", fragment=fragment, fetch=fetch
    )


@router.get("/runs/{run_id}/verify")
async def verify_page(
    request: Request,
    run_id: RunIdDep,
    console: ConsoleDep,
    signed: SignedInDep,
    fragment: bool = False,
) -> Response:
    def fetch() -> dict[str, Any]:
        report = verify_trace(sessions=sessions_of(request), run_id=run_id)
        return {"title": "Chain verification", "heading": "Chain verification", "report": report}

    return await _part(
        request, console, signed, run_id=run_id, template="verify", fragment=fragment, fetch=fetch
    )


@router.get("/runs/{run_id}/diff")
async def diff_page(
    request: Request,
    run_id: RunIdDep,
    console: ConsoleDep,
    signed: SignedInDep,
    fragment: bool = False,
) -> Response:
    """A revision against its parent (as GET /runs/{id}/diff), its long lists cut short."""

    def fetch() -> dict[str, Any]:
        part = views.diff_view(sessions=sessions_of(request), run_id=run_id)
        heading = f"Revision {run_id} against its parent"
        return {"title": "Revision diff", "heading": heading, "dv": part}

    return await _part(
        request, console, signed, run_id=run_id, template="diff", fragment=fragment, fetch=fetch
    )


@router.get("/runs/{run_id}/export.jsonl")
async def export(
    request: Request, run_id: RunIdDep, console: ConsoleDep, signed: SignedInDep
) -> Response:
    """The whole audit record as JSON lines (as GET /runs/{id}/trace?format=jsonl), as a
    download: the one record, read through the same pages."""
    try:
        response = jsonl_trace(sessions=sessions_of(request), run_id=run_id)
    except RunNotFoundError:
        raise no_run(request, run_id) from None
    response.headers["Content-Disposition"] = f'attachment; filename="run-{run_id}.jsonl"'
    return finish(request, response)


async def _act(
    request: Request, console: ConsoleDep, signed: CsrfDep, run_id: str, action: str
) -> Response:
    runs = request.app.state.runs
    command = service.cancel_run if action == "cancel" else service.resume_run
    try:
        await _in_run(
            request, run_id, command, sessions=runs.sessions, worker=runs.worker, run_id=run_id
        )
    except RunStateConflictError as exc:
        return console.refused(
            request,
            title=f"Cannot {action}",
            message=exc.message,
            retry=f"/console/runs/{run_id}",
            signed=signed,
            status_code=409,
        )
    return RedirectResponse(f"/console/runs/{run_id}", status_code=303)


@router.post("/runs/{run_id}/signoff")
async def sign_off(
    request: Request,
    run_id: RunIdDep,
    console: ConsoleDep,
    signed: CsrfDep,
    statement: Annotated[str, Form(max_length=MAX_STATEMENT_CHARS)] = "",
) -> Response:
    """The console's sign-off form: the same service as POST /runs/{id}/signoff, signed with
    the session key's name."""

    def refuse(message: str, status_code: int) -> Response:
        return console.refused(
            request,
            title="Not signed off",
            message=message,
            retry=f"/console/runs/{run_id}",
            signed=signed,
            status_code=status_code,
        )

    if not statement.strip():
        return refuse("A sign-off needs a statement.", 422)
    try:
        await _in_run(
            request,
            run_id,
            signoff.sign_off,
            sessions=sessions_of(request),
            run_id=run_id,
            signer=signed.name,
            statement=statement.strip(),
        )
    except RunStateConflictError as exc:
        return refuse(exc.message, 409)
    except DomainError as exc:
        if exc.status_code != 422:
            raise
        # The statement itself (a NUL character): say so on a page, like a blank one.
        return refuse(f"The statement {exc.message}.", 422)
    return RedirectResponse(f"/console/runs/{run_id}#signoffs", status_code=303)


@router.post("/runs/{run_id}/cancel")
async def cancel(
    request: Request, run_id: RunIdDep, console: ConsoleDep, signed: CsrfDep
) -> Response:
    return await _act(request, console, signed, run_id, "cancel")


@router.post("/runs/{run_id}/resume")
async def resume(
    request: Request, run_id: RunIdDep, console: ConsoleDep, signed: CsrfDep
) -> Response:
    return await _act(request, console, signed, run_id, "resume")
