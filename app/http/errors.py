"""One shape for every 4xx body: FastAPI's own `{"detail": [{"loc", "msg", "type"}]}`.

Clients then parse validation errors, domain errors (infeasible cap, unknown solver,
...), 404s and 413s the same way, and `loc` always points into the request.
"""

from __future__ import annotations

import logging
from collections.abc import Iterable, Sequence
from typing import Any

from fastapi import FastAPI, HTTPException, Request
from fastapi.concurrency import run_in_threadpool
from fastapi.exceptions import RequestValidationError
from fastapi.responses import JSONResponse
from fastapi.routing import iter_route_contexts
from starlette.exceptions import HTTPException as StarletteHTTPException

from app.domain.errors import DomainError, RunArchivedError, RunNotFoundError
from app.store.tombstones import archive_file_of

Loc = Sequence[str | int]
log = logging.getLogger("ltaa.api")


def error_item(loc: Loc, msg: str, type_: str) -> dict[str, Any]:
    return {"loc": list(loc), "msg": msg, "type": type_}


def error_body(loc: Loc, msg: str, type_: str) -> dict[str, Any]:
    return {"detail": [error_item(loc, msg, type_)]}


def field_loc(field: str, root: str = "body") -> list[str | int]:
    """'tasks.3.features' -> ['body', 'tasks', 3, 'features']: list indices as ints, like pydantic.

    A key under `success` is a feature name and stays a string even if it looks like a number.
    """
    loc: list[str | int] = [root]
    for part in filter(None, field.split(".")):
        loc.append(int(part) if part.isdigit() and loc[-1] != "success" else part)
    return loc


def domain_error_body(exc: DomainError) -> dict[str, Any]:
    return error_body(field_loc(exc.field, exc.location), exc.message, exc.code)


def validation_error_body(errors: Iterable[Any], root: Loc = ()) -> dict[str, Any]:
    """Pydantic/FastAPI error dicts reduced to loc/msg/type.

    `input` is dropped on purpose: for a 10,001-task list it would echo the whole body.
    """
    detail = []
    for err in errors:
        msg = str(err.get("msg", "invalid value"))
        ctx = err.get("ctx") or {}
        if err.get("type") == "json_invalid" and ctx.get("error"):
            msg = f"{msg}: {ctx['error']}"  # say *what* is wrong with the JSON, not just that it is
        elif tuple(err.get("loc", ())) == ("body",) and err.get("type") == "missing":
            msg = "a JSON object request body is required"
        loc = [*root, *err.get("loc", ())]
        detail.append(error_item(loc, msg, str(err.get("type", "invalid"))))
    return {"detail": detail}


class ApiError(HTTPException):
    """An HTTP error that names the part of the request at fault, e.g. 404 on ('path', 'run_id').

    A FastAPI HTTPException so that, raised while FastAPI reads the body, it passes through
    unchanged instead of becoming a generic 400.
    """

    def __init__(
        self,
        status_code: int,
        loc: Loc,
        msg: str,
        type_: str,
        headers: dict[str, str] | None = None,
    ) -> None:
        super().__init__(status_code, detail=msg, headers=headers)
        self.loc = list(loc)
        self.type = type_


# FastAPI raises a bare 400 only when it cannot read the body (e.g. a 5,000-digit integer).
_DEFAULT_LOC = {
    400: ["body"],
    401: ["header", "authorization"],
    403: ["header", "authorization"],
    404: ["path"],
    405: ["method"],
    413: ["body"],
}
_DEFAULT_TYPE = {
    400: "body_unreadable",
    401: "not_authenticated",
    403: "forbidden",
    404: "not_found",
    405: "method_not_allowed",
    409: "conflict",
    413: "too_large",
}


async def _on_validation(_: Request, exc: RequestValidationError) -> JSONResponse:
    return JSONResponse(validation_error_body(exc.errors()), status_code=422)


async def _on_domain(request: Request, exc: DomainError) -> JSONResponse:
    if isinstance(exc, RunNotFoundError):
        exc = await run_in_threadpool(_archived_or, request, exc)
    return JSONResponse(domain_error_body(exc), status_code=exc.status_code)


def _archived_or(request: Request, exc: RunNotFoundError) -> DomainError:
    """A run id with no row that was archived is 410 Gone naming its file, whichever route
    looked it up (docs/operations.md#archive), at the place in the request the lookup named."""
    runs = getattr(request.app.state, "runs", None)
    if runs is None:
        return exc
    archived = archive_file_of(sessions=runs.sessions, run_id=exc.run_id)
    if archived is None:
        return exc
    gone = RunArchivedError(exc.run_id, archived)
    gone.field, gone.location = exc.field, exc.location
    return gone


def _allowed_methods(request: Request) -> str:
    """Every method of the path. Starlette's 405 lists only the first route matching the path,
    e.g. `Allow: POST` for /runs, whose GET is a separate route."""
    methods: set[str] = set()
    for route in iter_route_contexts(request.app.router.routes):
        path_regex = getattr(route, "path_regex", None)
        if path_regex is not None and path_regex.match(request.scope["path"]):
            methods |= route.methods or set()
    return ", ".join(sorted(methods))


async def _on_http(request: Request, exc: StarletteHTTPException) -> JSONResponse:
    code = exc.status_code
    headers = exc.headers
    if code == 405:
        headers = {**(headers or {}), "Allow": _allowed_methods(request)}
    if isinstance(exc, ApiError):
        body = error_body(exc.loc, str(exc.detail), exc.type)
    elif isinstance(exc.detail, list):  # already in list form
        body = {"detail": exc.detail}
    else:
        body = error_body(
            _DEFAULT_LOC.get(code, ["request"]),
            str(exc.detail),
            _DEFAULT_TYPE.get(code, "http_error"),
        )
    return JSONResponse(body, status_code=code, headers=headers)


async def _on_unexpected(request: Request, exc: Exception) -> JSONResponse:
    # A bug, not bad input: still JSON, with no internals; the traceback goes to the log.
    log.exception("unhandled error on %s %s", request.method, request.url.path)
    return JSONResponse(
        error_body(["server"], "internal error; the server log has the details", "internal_error"),
        status_code=500,
    )


def install_error_handlers(app: FastAPI) -> None:
    # Starlette types a handler as taking any Exception; ours take the one class they handle.
    app.add_exception_handler(RequestValidationError, _on_validation)  # type: ignore[arg-type]
    app.add_exception_handler(DomainError, _on_domain)  # type: ignore[arg-type]
    app.add_exception_handler(StarletteHTTPException, _on_http)  # type: ignore[arg-type]
    app.add_exception_handler(Exception, _on_unexpected)
