"""GET /console/reviews: the queue of decisions waiting for a supervisor, and the approve /
override forms that resolve one (the same service as POST /runs/{id}/reviews/{task_index})."""

from __future__ import annotations

import json
from typing import Annotated

from fastapi import APIRouter, Form, Path, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import RedirectResponse, Response

from app.console.context import (
    ConsoleDep,
    CsrfDep,
    RunIdDep,
    SignedInDep,
    finish,
    no_run,
    sessions_of,
)
from app.domain.errors import DomainError, RunNotFoundError
from app.domain.review import ReviewAction
from app.reviews import service as review_service

router = APIRouter(prefix="/console", include_in_schema=False)


def _pending(request: Request) -> list[review_service.PendingReview]:
    return review_service.pending_reviews(sessions=sessions_of(request))


@router.get("/reviews")
async def reviews_page(request: Request, console: ConsoleDep, signed: SignedInDep) -> Response:
    pending = await run_in_threadpool(_pending, request)
    context = {"title": "Reviews", "reviews": pending, "available": True}
    return finish(request, console.render(request, "reviews.html", context, signed=signed))


@router.post("/runs/{run_id}/reviews/{task_index}")
async def resolve(
    request: Request,
    run_id: RunIdDep,
    task_index: Annotated[int, Path(ge=0, le=1_000_000)],
    console: ConsoleDep,
    signed: CsrfDep,
    action: Annotated[str, Form(max_length=16)] = "",
    robot: Annotated[str | None, Form(max_length=200)] = None,
    reason: Annotated[str | None, Form(max_length=2000)] = None,
    team: Annotated[str | None, Form(max_length=20_000)] = None,
) -> Response:
    runs = request.app.state.runs
    try:
        chosen = ReviewAction(action)
        override = chosen is ReviewAction.OVERRIDE
        resolved = await run_in_threadpool(
            review_service.resolve,
            sessions=runs.sessions,
            run_id=run_id,
            task_index=task_index,
            action=chosen,
            robot=(robot or None) if override else None,
            team=_team(team) if override and team else None,
            reason=reason,
            reviewer=signed.name,
        )
    except RunNotFoundError:
        raise no_run(request, run_id) from None
    except ValueError as exc:  # DomainError is a ValueError too: unknown action, robot...
        status = getattr(exc, "status_code", 422) if isinstance(exc, DomainError) else 422
        message = exc.message if isinstance(exc, DomainError) else f"unknown action '{action}'"
        return console.refused(
            request,
            title="Review not resolved",
            message=message,
            retry="/console/reviews",
            signed=signed,
            status_code=status,
        )
    request.app.state.metrics.review_resolved(resolved.waited_s)
    runs.worker.submit(run_id)
    return RedirectResponse(f"/console/runs/{run_id}", status_code=303)


def _team(value: str) -> list[tuple[str, str]]:
    """The team form field: the chosen candidate team as JSON (the select's values), one
    {"robot", "feature"} per unit; the service checks it as a team."""
    try:
        members = json.loads(value)
    except (ValueError, RecursionError) as exc:  # deep nesting: RecursionError, not a 500
        raise DomainError("team", "not a team: choose one of the listed teams") from exc
    if not isinstance(members, list) or not all(
        isinstance(m, dict)
        and isinstance(m.get("robot"), str)
        and isinstance(m.get("feature"), str)
        for m in members
    ):
        raise DomainError("team", "not a team: choose one of the listed teams")
    return [(m["robot"], m["feature"]) for m in members]
