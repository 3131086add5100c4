"""The error responses each route documents in the OpenAPI, all in the one error shape.

Clients generated from /openapi.json (and schemathesis in the tests) then know every status
a route can answer with and that every error body is `{"detail": [{"loc", "msg", "type"}]}`.
"""

from __future__ import annotations

from collections.abc import Callable
from typing import Any

from pydantic import BaseModel, Field


class ErrorItem(BaseModel):
    loc: list[str | int] = Field(
        description="Where in the request: ['body', 'tasks', 3, 'id'], "
        "['path', 'run_id'], ['header', 'idempotency-key'], ..."
    )
    msg: str = Field(description="What is wrong and how to fix it")
    type: str = Field(description="A stable, machine-readable error code")


class ErrorOut(BaseModel):
    """The body of every 4xx (and of an unexpected 5xx)."""

    detail: list[ErrorItem]


_WHEN: dict[int, str] = {
    400: "The body could not be read at all (e.g. a number too long to parse)",
    401: "No API key, or not a valid one (only when LTAA_API_KEYS is set)",
    403: "The API key's role may not call this endpoint",
    404: "No run with this id",
    409: "The request conflicts with the run's state or with an earlier request",
    410: "The run was archived: the message names its archive file",
    413: "The body is larger than LTAA_MAX_BODY_BYTES",
    422: "The request is invalid; `loc` names the field and `msg` says how to fix it",
    502: "The Messages API refused the server's own credentials (ANTHROPIC_API_KEY)",
    503: "Runs did not reach a node boundary in time for a backup; retry",
}


def errors(*codes: int) -> dict[int | str, dict[str, Any]]:
    """`responses=` for a route: each status documented with the one error shape."""
    return {code: {"model": ErrorOut, "description": _WHEN[code]} for code in codes}


# Every endpoint behind an API key: a client key passes everywhere a client may go.
CLIENT = (401, 422)
SUPERVISOR = (401, 403, 422)
BODY = (400, 413)  # endpoints that read a JSON body


def header_schema(**string: Any) -> Callable[[dict[str, Any]], None]:
    """json_schema_extra of an optional header: a string with these keywords. Optional
    means not sent; a header has no null (`str | None` would document one, and a client
    would send the text "null")."""

    def edit(schema: dict[str, Any]) -> None:
        kept: dict[str, Any] = {k: schema[k] for k in ("title", "description") if k in schema}
        schema.clear()
        schema.update(kept, type="string", **string)

    return edit
