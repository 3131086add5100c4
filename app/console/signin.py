"""GET/POST /console/login and /console/logout."""

from __future__ import annotations

import hmac
import logging
from typing import Annotated

from fastapi import APIRouter, Form, Query, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.responses import RedirectResponse, Response

from app.console import sessions
from app.console.context import (
    ConsoleDep,
    CsrfDep,
    finish,
    safe_next,
    sessions_of,
    set_session_cookie,
    signed_in_or_none,
)
from app.console.sessions import COOKIE, LOGIN_CSRF_COOKIE
from app.http.auth import Role

router = APIRouter(prefix="/console", include_in_schema=False)
log = logging.getLogger("ltaa.console")
LOGIN_FORM_S = 3600


def _login_page(
    request: Request,
    console: ConsoleDep,
    *,
    next_: str,
    error: str | None = None,
    status_code: int = 200,
) -> Response:
    # The form's CSRF token before there is a session: the same random value in a cookie
    # (SameSite=Strict, so another site's form cannot carry it) and in a hidden field.
    token = sessions.new_token()
    response = console.render(
        request,
        "login.html",
        {"title": "Sign in", "next": next_, "login_csrf": token, "error": error},
        status_code=status_code,
    )
    response.set_cookie(
        LOGIN_CSRF_COOKIE,
        token,
        max_age=LOGIN_FORM_S,
        path="/console/login",
        httponly=True,
        samesite="strict",
        secure=request.url.scheme == "https",
    )
    return response


@router.get("/login")
async def login_form(
    request: Request,
    console: ConsoleDep,
    next_: Annotated[str | None, Query(alias="next", max_length=2000)] = None,
) -> Response:
    target = safe_next(next_)
    signed = await run_in_threadpool(signed_in_or_none, request)
    if console.keyring.open or signed is not None:
        return console.render(
            request, "login.html", {"title": "Sign in", "next": target, "signed_in": True}
        )
    return _login_page(request, console, next_=target)


@router.post("/login")
async def login(
    request: Request,
    console: ConsoleDep,
    api_key: Annotated[str, Form(max_length=4096)] = "",
    csrf_token: Annotated[str, Form(max_length=256)] = "",
    next_: Annotated[str, Form(alias="next", max_length=2000)] = "/console",
) -> Response:
    expected = request.cookies.get(LOGIN_CSRF_COOKIE, "")
    if not csrf_token or not expected or not hmac.compare_digest(csrf_token, expected):
        return console.refused(
            request,
            title="Form refused",
            message="The sign-in form was sent without its security token (or from "
            "another site). Open the sign-in page again and sign in from there.",
            retry="/console/login",
            status_code=403,
        )
    target = safe_next(next_)
    if console.keyring.open:
        return RedirectResponse(target, status_code=303)
    found = console.keyring.fingerprint_of(api_key.strip()) if api_key.strip() else None
    if found is None:
        log.warning(
            "console sign-in refused: unknown key, from %s",
            request.client.host if request.client else "?",
        )
        return _login_page(
            request,
            console,
            next_=target,
            error="That key is not a configured API key. Check it and try again.",
            status_code=401,
        )
    role, fingerprint = found
    if role is not Role.SUPERVISOR:
        return console.refused(
            request,
            title="Client key refused",
            message="This is a client key: it lets the site app allocate and "
            "create runs, but the console is for supervisors. Sign in with a "
            "supervisor key.",
            retry="/console/login",
            status_code=403,
        )
    identified = console.keyring.identify_fingerprint(fingerprint)
    signed = await run_in_threadpool(
        sessions.open_session,
        sessions=sessions_of(request),
        fingerprint=fingerprint,
        lifetime_s=console.settings.console_session_s,
        name=identified[1] if identified else fingerprint[:8],
    )
    response = RedirectResponse(target, status_code=303)
    set_session_cookie(request, response, signed, console.settings.console_session_s)
    response.delete_cookie(LOGIN_CSRF_COOKIE, path="/console/login")
    return response


@router.get("/logout")
async def logout_form(request: Request, console: ConsoleDep) -> Response:
    signed = await run_in_threadpool(signed_in_or_none, request)
    if signed is None:
        return RedirectResponse("/console/login", status_code=303)
    return console.render(request, "logout.html", {"title": "Sign out"}, signed=signed)


@router.post("/logout")
async def logout(request: Request, signed: CsrfDep) -> Response:
    await run_in_threadpool(
        sessions.close_session, sessions=sessions_of(request), token=signed.token
    )
    response = RedirectResponse("/console/login", status_code=303)
    response.delete_cookie(COOKIE, path="/")
    return finish(request, response)
