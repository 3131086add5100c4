"""What every console route shares: the templates, who is signed in, the CSRF check, and
HTML answers for the failures a person can meet (sign-in needed, refused form, no run)."""

from __future__ import annotations

import hmac
import re
from dataclasses import dataclass
from pathlib import Path
from typing import Annotated, Any
from urllib.parse import quote

from fastapi import Depends, Form, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import HTMLResponse, RedirectResponse, Response
from fastapi.templating import Jinja2Templates
from sqlalchemy.orm import Session, sessionmaker

from app.config import Settings
from app.console import format as fmt
from app.console import sessions
from app.console.sessions import COOKIE, SignedIn
from app.http.auth import Caller, KeyRing, Role
from app.runs.schemas import RUN_ID_PATTERN
from app.store import tombstones

HERE = Path(__file__).resolve().parent


@dataclass(frozen=True)
class Console:
    templates: Jinja2Templates
    keyring: KeyRing
    settings: Settings

    @classmethod
    def build(cls, *, keyring: KeyRing, settings: Settings) -> Console:
        templates = Jinja2Templates(directory=HERE / "templates")
        templates.env.filters.update(fmt.FILTERS)
        return cls(templates=templates, keyring=keyring, settings=settings)

    def refused(
        self,
        request: Request,
        *,
        title: str,
        message: str,
        retry: str | None = None,
        signed: SignedIn | None = None,
        status_code: int,
    ) -> HTMLResponse:
        """The page that says what was refused and why, with a way back (`retry`)."""
        context = {"title": title, "message": message}
        if retry is not None:
            context["retry"] = retry
        return self.render(request, "refused.html", context, signed=signed, status_code=status_code)

    def render(
        self,
        request: Request,
        name: str,
        context: dict[str, Any],
        *,
        signed: SignedIn | None = None,
        status_code: int = 200,
    ) -> HTMLResponse:
        full = {"signed": signed, "open_access": self.keyring.open, **context}
        response = self.templates.TemplateResponse(
            request=request, name=name, context=full, status_code=status_code
        )
        # Pages show runs and reasoning: never from a shared cache, never framed elsewhere.
        response.headers["Cache-Control"] = "no-store"
        response.headers["X-Frame-Options"] = "DENY"
        response.headers["Content-Security-Policy"] = CSP
        return response


# Everything the pages load comes from this server: a stray external URL fails closed.
CSP = (
    "default-src 'self'; img-src 'self' data:; style-src 'self'; script-src 'self'; "
    "connect-src 'self'; form-action 'self'; frame-ancestors 'none'; base-uri 'none'"
)


def console_of(request: Request) -> Console:
    console: Console = request.app.state.console
    return console


def sessions_of(request: Request) -> sessionmaker[Session]:
    factory: sessionmaker[Session] = request.app.state.runs.sessions
    return factory


ConsoleDep = Annotated[Console, Depends(console_of)]


class SignInRequired(Exception):
    """A console page asked for without a live session: answered with the sign-in page."""

    def __init__(self, path: str) -> None:
        self.path = path


class PageNotFound(Exception):
    """No such run (or attempt): answered with a page saying so, a 404; an archived run's
    page is a 410 naming its archive file, as the JSON API answers."""

    def __init__(self, message: str, *, gone: bool = False) -> None:
        super().__init__(message)
        self.message = message
        self.gone = gone


def no_run(request: Request, run_id: str) -> PageNotFound:
    """What to answer for a run id with no row: archived (its file) or unknown."""
    archived = tombstones.archive_file_of(sessions=sessions_of(request), run_id=run_id)
    if archived is None:
        return PageNotFound(f"There is no run '{run_id}'.")
    return PageNotFound(
        f"Run '{run_id}' was archived to '{archived}' (in the server's archive directory): "
        "its record is that file, which scripts/check_trace.py verifies.",
        gone=True,
    )


def on_page_not_found(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, PageNotFound)
    title = "Archived" if exc.gone else "Not found"
    return console_of(request).refused(
        request, title=title, message=exc.message, status_code=410 if exc.gone else 404
    )


def run_id_of(run_id: str) -> str:
    """The path's run id, checked before any query (PostgreSQL refuses a NUL character)."""
    if re.fullmatch(RUN_ID_PATTERN, run_id) is None:
        raise PageNotFound(f"There is no run '{run_id[:64]}'.")
    return run_id


RunIdDep = Annotated[str, Depends(run_id_of)]


class CsrfRefused(Exception):
    """A console form posted without the CSRF token of its session."""


def set_session_cookie(
    request: Request, response: Response, signed: SignedIn, max_age: float
) -> None:
    response.set_cookie(
        COOKIE,
        signed.token,
        max_age=int(max_age),
        # "/" and not "/console": the run page's EventSource reads /runs/{id}/events.
        path="/",
        httponly=True,
        samesite="strict",
        secure=request.url.scheme == "https",
    )


def signed_in_or_none(request: Request) -> SignedIn | None:
    console = console_of(request)
    return sessions.current(
        sessions=sessions_of(request), keyring=console.keyring, token=request.cookies.get(COOKIE)
    )


async def require_signed_in(request: Request) -> SignedIn:
    """The live session, or (with access control off) a keyless one opened on the spot."""
    signed = await run_in_threadpool(signed_in_or_none, request)
    if signed is not None:
        return signed
    console = console_of(request)
    if console.keyring.open:
        fresh = await run_in_threadpool(
            sessions.open_session,
            sessions=sessions_of(request),
            fingerprint=None,
            lifetime_s=console.settings.console_session_s,
        )
        request.state.new_console_session = fresh
        return fresh
    target = request.url.path + (f"?{request.url.query}" if request.url.query else "")
    raise SignInRequired(target)


SignedInDep = Annotated[SignedIn, Depends(require_signed_in)]


async def require_csrf(
    signed: SignedInDep, csrf_token: Annotated[str | None, Form()] = None
) -> SignedIn:
    if not csrf_token or not hmac.compare_digest(csrf_token, signed.csrf_token):
        raise CsrfRefused()
    return signed


CsrfDep = Annotated[SignedIn, Depends(require_csrf)]


def finish(request: Request, response: Response) -> Response:
    """Attach the cookie of a keyless session opened during this request, if any."""
    fresh: SignedIn | None = getattr(request.state, "new_console_session", None)
    if fresh is not None:
        set_session_cookie(request, response, fresh, console_of(request).settings.console_session_s)
    return response


def on_sign_in_required(request: Request, exc: Exception) -> Response:
    assert isinstance(exc, SignInRequired)
    return RedirectResponse(f"/console/login?next={quote(exc.path, safe='/')}", status_code=303)


def on_csrf_refused(request: Request, exc: Exception) -> Response:
    return console_of(request).refused(
        request,
        title="Form refused",
        message="This form was sent without the security token of your session "
        "(it may come from another site, or from a page opened before you signed in "
        "again). Nothing was changed. Go back, reload the page and send it again.",
        status_code=403,
    )


def stream_cookie_auth(request: Request) -> Caller | None:
    """For app.http.deps: the console's session as a caller of the read-only event stream."""
    signed = signed_in_or_none(request)
    if signed is None:
        return None
    return Caller(role=Role.SUPERVISOR, anonymous=signed.anonymous, name=signed.name)


def safe_next(target: str | None) -> str:
    # Only a console path: never an open redirect to another site.
    if target and target.startswith("/console") and not target.startswith("//"):
        return target
    return "/console"
