"""The supervisor console: server-rendered pages under /console (README.md#console).

A thin layer over app.runs, the services the JSON API uses; its own state is only the
sign-in sessions. Pages load nothing from outside this server.
"""

from __future__ import annotations

from fastapi import FastAPI
from fastapi.staticfiles import StaticFiles

from app.config import Settings
from app.console import context, fleet, imports, pages, reviews, signin, sites
from app.http.auth import KeyRing


def install(app: FastAPI, *, keyring: KeyRing, settings: Settings) -> None:
    app.state.console = context.Console.build(keyring=keyring, settings=settings)
    # Read by app.http.deps for GET /runs/{id}/events only.
    app.state.stream_cookie_auth = context.stream_cookie_auth
    app.add_exception_handler(context.SignInRequired, context.on_sign_in_required)
    app.add_exception_handler(context.CsrfRefused, context.on_csrf_refused)
    app.add_exception_handler(context.PageNotFound, context.on_page_not_found)
    app.mount(
        "/console/static",
        StaticFiles(directory=context.HERE / "static"),
        name="console-static",
    )
    for module in (signin, pages, reviews, sites, fleet, imports):
        app.include_router(module.router)


__all__ = ["install"]
